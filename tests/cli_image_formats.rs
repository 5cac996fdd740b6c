//! Frames as webcams and V4L2 grabs save them (issue 16): `ffdic analyze` on PNG and BMP pairs
//! gives the result it gives on the same pixels as TIFF. The frames are DIC Challenge Sample 3
//! (8-bit TIFF, read by the TIFF path), re-encoded here by encoders independent of the reader
//! under test: PNG by the `png` crate, BMP written byte by byte below; 16-bit pairs by
//! scaling the same pixels by 257.

use crate::common;

use ffdic::image::{read_image, read_tiff, write_tiff_u16, Image};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

fn sample3(name: &str) -> PathBuf {
    common::shared_data()
        .join("dic-challenge-1/sample3")
        .join(name)
}

fn grey8(image: &Image) -> Vec<u8> {
    image.data().iter().map(|&v| v as u8).collect()
}

fn write_png(path: &Path, image: &Image, colour: png::ColorType, depth: png::BitDepth) {
    let mut out = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut out, image.width() as u32, image.height() as u32);
        encoder.set_color(colour);
        encoder.set_depth(depth);
        let mut writer = encoder.write_header().unwrap();
        let bytes: Vec<u8> = match (colour, depth) {
            (png::ColorType::Grayscale, png::BitDepth::Eight) => grey8(image),
            (png::ColorType::Grayscale, png::BitDepth::Sixteen) => image
                .data()
                .iter()
                .flat_map(|&v| (v as u16 * 257).to_be_bytes())
                .collect(),
            (png::ColorType::Rgb, png::BitDepth::Eight) => {
                grey8(image).into_iter().flat_map(|g| [g, g, g]).collect()
            }
            other => panic!("not used here: {other:?}"),
        };
        writer.write_image_data(&bytes).unwrap();
    }
    std::fs::write(path, out).unwrap();
}

/// An 8-bit palette BMP with a grey palette (what Windows tools save for grey images):
/// BITMAPFILEHEADER, BITMAPINFOHEADER, 256 palette entries, rows bottom-up padded to 4 bytes.
fn write_bmp8(path: &Path, image: &Image) {
    let (w, h) = (image.width(), image.height());
    let row = w.div_ceil(4) * 4;
    let pixels_at = 14 + 40 + 256 * 4;
    let size = pixels_at + row * h;
    let mut b = Vec::with_capacity(size);
    b.extend_from_slice(b"BM");
    b.extend_from_slice(&(size as u32).to_le_bytes());
    b.extend_from_slice(&[0; 4]);
    b.extend_from_slice(&(pixels_at as u32).to_le_bytes());
    b.extend_from_slice(&40u32.to_le_bytes());
    b.extend_from_slice(&(w as i32).to_le_bytes());
    b.extend_from_slice(&(h as i32).to_le_bytes());
    b.extend_from_slice(&1u16.to_le_bytes()); // planes
    b.extend_from_slice(&8u16.to_le_bytes()); // bits per pixel
    b.extend_from_slice(&0u32.to_le_bytes()); // no compression
    b.extend_from_slice(&((row * h) as u32).to_le_bytes());
    b.extend_from_slice(&2835i32.to_le_bytes()); // 72 dpi
    b.extend_from_slice(&2835i32.to_le_bytes());
    b.extend_from_slice(&256u32.to_le_bytes()); // palette entries
    b.extend_from_slice(&0u32.to_le_bytes());
    for g in 0..=255u8 {
        b.extend_from_slice(&[g, g, g, 0]);
    }
    let grey = grey8(image);
    for r in (0..h).rev() {
        b.extend_from_slice(&grey[r * w..(r + 1) * w]);
        b.extend(std::iter::repeat_n(0u8, row - w));
    }
    assert_eq!(b.len(), size);
    std::fs::write(path, b).unwrap();
}

/// `ffdic analyze --json` of a pair, without its wall time and the file names it echoes.
fn analyze(reference: &Path, deformed: &Path) -> Value {
    let out = Command::new(env!("CARGO_BIN_EXE_ffdic"))
        .arg("analyze")
        .arg(reference)
        .arg(deformed)
        .args(["--subset", "21", "--step", "16", "--json"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut doc: Value = serde_json::from_slice(&out.stdout).unwrap();
    doc.as_object_mut().unwrap().remove("elapsed_s");
    let settings = doc["settings"].as_object_mut().unwrap();
    settings.remove("reference");
    settings.remove("deformed");
    doc
}

#[test]
fn png_and_bmp_pairs_analyse_as_their_tiff_twins() {
    let tmp = tempfile::tempdir().unwrap();
    let (reference, _) = read_tiff(&sample3("reference.tif")).unwrap();
    let (deformed, info) = read_tiff(&sample3("shift_05.tif")).unwrap();
    assert_eq!(info.bit_depth, 8, "Sample 3 is 8-bit");
    let tiff = analyze(&sample3("reference.tif"), &sample3("shift_05.tif"));
    assert!(tiff["valid"].as_u64().unwrap() > 100, "{tiff}");

    type Writer = fn(&Path, &Image);
    let formats: [(&str, Writer); 3] = [
        ("grey.png", |p, i| {
            write_png(p, i, png::ColorType::Grayscale, png::BitDepth::Eight)
        }),
        ("rgb.png", |p, i| {
            write_png(p, i, png::ColorType::Rgb, png::BitDepth::Eight)
        }),
        ("grey.bmp", write_bmp8),
    ];
    for (name, write) in formats {
        let (r, d) = (
            tmp.path().join(format!("ref-{name}")),
            tmp.path().join(format!("def-{name}")),
        );
        write(&r, &reference);
        write(&d, &deformed);
        let (back, info) = read_image(&r).unwrap();
        assert_eq!(back, reference, "{name}: the pixels read back");
        assert_eq!(info.bit_depth, 8, "{name}");
        assert_eq!(
            analyze(&r, &d),
            tiff,
            "{name}: the same analysis as the TIFF pair"
        );
    }

    // 16 bit: the same pixels x 257 as 16-bit TIFF (the TIFF writer) and 16-bit grey PNG.
    let scale = |i: &Image| {
        Image::from_vec(
            i.width(),
            i.height(),
            i.data().iter().map(|v| v * 257.0).collect(),
        )
        .unwrap()
    };
    let (r16, d16) = (scale(&reference), scale(&deformed));
    let paths = |ext: &str| {
        (
            tmp.path().join(format!("ref16.{ext}")),
            tmp.path().join(format!("def16.{ext}")),
        )
    };
    let (rt, dt) = paths("tif");
    write_tiff_u16(&rt, &r16).unwrap();
    write_tiff_u16(&dt, &d16).unwrap();
    let (rp, dp) = paths("png");
    write_png(
        &rp,
        &reference,
        png::ColorType::Grayscale,
        png::BitDepth::Sixteen,
    );
    write_png(
        &dp,
        &deformed,
        png::ColorType::Grayscale,
        png::BitDepth::Sixteen,
    );
    let (back, info) = read_image(&rp).unwrap();
    assert_eq!((back, info.bit_depth), (r16, 16));
    assert_eq!(analyze(&rp, &dp), analyze(&rt, &dt), "16-bit PNG and TIFF");
}

#[test]
fn a_frame_of_another_format_is_refused_naming_the_ones_read() {
    let tmp = tempfile::tempdir().unwrap();
    let jpeg = tmp.path().join("frame.jpg");
    std::fs::write(
        &jpeg,
        [0xFF, 0xD8, 0xFF, 0xE0, 0, 16, b'J', b'F', b'I', b'F'],
    )
    .unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_ffdic"))
        .arg("analyze")
        .arg(&jpeg)
        .arg(sample3("shift_05.tif"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("TIFF, PNG or BMP"), "{err}");
    // A PNG cut short is a decode error naming the file, not a panic.
    let (reference, _) = read_tiff(&sample3("reference.tif")).unwrap();
    let png = tmp.path().join("cut.png");
    write_png(
        &png,
        &reference,
        png::ColorType::Grayscale,
        png::BitDepth::Eight,
    );
    let bytes = std::fs::read(&png).unwrap();
    std::fs::write(&png, &bytes[..bytes.len() / 2]).unwrap();
    let e = read_image(&png).unwrap_err().to_string();
    assert!(e.contains("cut.png"), "{e}");
}
