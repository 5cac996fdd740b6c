//! V4L2 luma buffers into 16-bit samples, as pure functions over bytes.
//!
//! Lines start `bytes_per_line` apart (`v4l2_pix_format.bytesperline`, V4L2 UAPI "Single-planar
//! format structure"): a driver may pad every line, so the stride can exceed the line itself.
//! Every read is bounds-checked up front: a short buffer is an error, never a panic.

use crate::format::{fourcc_name, V4l2Format};

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum UnpackError {
    #[error("pixel format {name} (0x{fourcc:08x}) is not GREY, Y10, Y12, Y16, Y10P or Y12P")]
    UnsupportedFormat { fourcc: u32, name: String },
    #[error("bytes per line {bytes_per_line} is shorter than a {format} line of {width} px ({line_bytes} bytes)")]
    StrideTooShort {
        format: V4l2Format,
        width: usize,
        bytes_per_line: usize,
        line_bytes: usize,
    },
    #[error(
        "{got_bytes} bytes hold less than a {width}x{height} {format} image ({need_bytes} bytes)"
    )]
    ShortBuffer {
        format: V4l2Format,
        width: usize,
        height: usize,
        need_bytes: usize,
        got_bytes: usize,
    },
    #[error("a {width}x{height} image does not fit in memory")]
    TooLarge { width: usize, height: usize },
}

/// Decodes the image of FourCC `fourcc` in `bytes` into `width × height` samples, row-major,
/// without padding. Samples keep their value (a 10-bit format gives 0..=1023).
pub fn unpack(
    fourcc: u32,
    bytes: &[u8],
    width: usize,
    height: usize,
    bytes_per_line: usize,
) -> Result<Vec<u16>, UnpackError> {
    let format = V4l2Format::from_fourcc(fourcc).ok_or_else(|| UnpackError::UnsupportedFormat {
        fourcc,
        name: fourcc_name(fourcc),
    })?;
    unpack_format(format, bytes, width, height, bytes_per_line)
}

/// `unpack` for a format already known to be supported.
pub fn unpack_format(
    format: V4l2Format,
    bytes: &[u8],
    width: usize,
    height: usize,
    bytes_per_line: usize,
) -> Result<Vec<u16>, UnpackError> {
    let too_large = UnpackError::TooLarge { width, height };
    let line_bytes = format.line_bytes(width).ok_or(too_large.clone())?;
    if height > 0 && bytes_per_line < line_bytes {
        return Err(UnpackError::StrideTooShort {
            format,
            width,
            bytes_per_line,
            line_bytes,
        });
    }
    let need_bytes = format
        .image_bytes(width, height, bytes_per_line)
        .ok_or(too_large.clone())?;
    if bytes.len() < need_bytes {
        return Err(UnpackError::ShortBuffer {
            format,
            width,
            height,
            need_bytes,
            got_bytes: bytes.len(),
        });
    }
    let samples = width.checked_mul(height).ok_or(too_large)?;
    let mut out = Vec::with_capacity(samples);
    // From here on every line [start, start + line_bytes) lies inside `bytes` (checked above).
    for row in 0..height {
        let start = row * bytes_per_line;
        let line = &bytes[start..start + line_bytes];
        match format {
            V4l2Format::Grey => out.extend(line.iter().map(|&b| u16::from(b))),
            V4l2Format::Y10 | V4l2Format::Y12 | V4l2Format::Y16 => {
                // The spec pads the high bits with zeros; the mask keeps Frame's promise that a
                // sample fits its bit depth even when a driver leaves garbage there.
                let mask = u16::MAX >> (16 - u32::from(format.bit_depth()));
                out.extend(
                    line.chunks_exact(2)
                        .map(|w| u16::from_le_bytes([w[0], w[1]]) & mask),
                );
            }
            V4l2Format::Y10P => unpack_raw10_line(line, width, &mut out),
            V4l2Format::Y12P => unpack_raw12_line(line, width, &mut out),
        }
    }
    Ok(out)
}

/// MIPI RAW10 (V4L2 `Y10P`): bytes 0–3 of a group are the 8 high bits of pixels 0–3, byte 4
/// their 2 low bits, pixel 0 in bits 1:0 up to pixel 3 in bits 7:6.
fn unpack_raw10_line(line: &[u8], width: usize, out: &mut Vec<u16>) {
    let mut left = width;
    for group in line.chunks_exact(5) {
        let low = group[4];
        for (i, &high) in group[..4].iter().enumerate().take(left) {
            out.push((u16::from(high) << 2) | u16::from((low >> (2 * i)) & 0b11));
        }
        left = left.saturating_sub(4);
    }
}

/// MIPI RAW12 (V4L2 `Y12P`): bytes 0–1 of a group are the 8 high bits of pixels 0–1, byte 2
/// their 4 low bits, pixel 0 in bits 3:0 and pixel 1 in bits 7:4.
fn unpack_raw12_line(line: &[u8], width: usize, out: &mut Vec<u16>) {
    let mut left = width;
    for group in line.chunks_exact(3) {
        let low = group[2];
        for (i, &high) in group[..2].iter().enumerate().take(left) {
            out.push((u16::from(high) << 4) | u16::from((low >> (4 * i)) & 0x0f));
        }
        left = left.saturating_sub(2);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::format::*;

    #[test]
    fn grey_with_padded_stride() {
        // 3x2, stride 5: two padding bytes (0xEE) end each line.
        let bytes = [1, 2, 255, 0xEE, 0xEE, 4, 5, 6, 0xEE, 0xEE];
        let v = unpack(FOURCC_GREY, &bytes, 3, 2, 5).unwrap();
        assert_eq!(v, vec![1, 2, 255, 4, 5, 6]);
    }

    #[test]
    fn y10_y12_y16_little_endian_words_with_padding() {
        // 2x2, stride 6 (one 2-byte pad per line, 0xFF so a leak would show).
        let bytes = [
            0xFF, 0x03, 0x01, 0x02, 0xFF, 0xFF, //
            0x34, 0x12, 0x00, 0x00, 0xFF, 0xFF,
        ];
        let y16 = unpack(FOURCC_Y16, &bytes, 2, 2, 6).unwrap();
        assert_eq!(y16, vec![0x03FF, 0x0201, 0x1234, 0x0000]);
        let y12 = unpack(FOURCC_Y12, &bytes, 2, 2, 6).unwrap();
        assert_eq!(y12, vec![0x03FF, 0x0201, 0x0234, 0x0000]);
        let y10 = unpack(FOURCC_Y10, &bytes, 2, 2, 6).unwrap();
        assert_eq!(y10, vec![0x03FF, 0x0201, 0x0234, 0x0000]);
        assert_eq!(y10[0], 1023);
    }

    #[test]
    fn y10p_groups_of_four_in_five_bytes() {
        // Pixels 1023, 0, 514, 3 → high bytes 0xFF, 0x00, 0x80, 0x00; low bits 11, 00, 10, 11
        // → byte 4 = 0b11_10_00_11 = 0xE3. Second line: 4, 8, 12, 16 → high 1, 2, 3, 4, low 0.
        // Stride 7: two pad bytes per line.
        let bytes = [
            0xFF, 0x00, 0x80, 0x00, 0xE3, 0xAA, 0xAA, //
            0x01, 0x02, 0x03, 0x04, 0x00, 0xAA, 0xAA,
        ];
        let v = unpack(FOURCC_Y10P, &bytes, 4, 2, 7).unwrap();
        assert_eq!(v, vec![1023, 0, 514, 3, 4, 8, 12, 16]);
    }

    #[test]
    fn y10p_width_not_a_multiple_of_four() {
        // 6 px: a full group, then a group whose pixels 2 and 3 are padding (0x77).
        // Pixels 1, 2, 3, 4 → high 0, 0, 0, 1; low 01, 10, 11, 00 → byte 4 = 0b00_11_10_01.
        // Pixels 5, 6 → high 1, 1; low 01, 10 → byte 4 = 0b00_00_10_01.
        let bytes = [0, 0, 0, 1, 0b0011_1001, 1, 1, 0x77, 0x77, 0b0000_1001];
        let v = unpack(FOURCC_Y10P, &bytes, 6, 1, 10).unwrap();
        assert_eq!(v, vec![1, 2, 3, 4, 5, 6]);
    }

    #[test]
    fn y12p_pairs_in_three_bytes_with_padding() {
        // 4095, 0x123 → high 0xFF, 0x12; low 0xF and 0x3 → byte 2 = 0x3F.
        // 0x800, 0x001 → high 0x80, 0x00; low 0x0 and 0x1 → 0x10. Stride 8 (two pad bytes).
        let bytes = [
            0xFF, 0x12, 0x3F, 0x80, 0x00, 0x10, 0x55, 0x55, //
            0x00, 0x00, 0x00, 0x01, 0x01, 0xF0, 0x55, 0x55,
        ];
        let v = unpack(FOURCC_Y12P, &bytes, 4, 2, 8).unwrap();
        assert_eq!(v, vec![4095, 0x123, 0x800, 0x001, 0, 0, 0x010, 0x01F]);
    }

    #[test]
    fn y12p_odd_width_reads_its_half_group() {
        // 3 px: 0xABC, 0x001, 0x456 → [AB, 00, 1C] [45, pad, x6].
        let bytes = [0xAB, 0x00, 0x1C, 0x45, 0x99, 0x06];
        let v = unpack(FOURCC_Y12P, &bytes, 3, 1, 6).unwrap();
        assert_eq!(v, vec![0xABC, 0x001, 0x456]);
    }

    #[test]
    fn short_buffers_are_errors_not_panics() {
        // 4x2 Y16 at stride 10 needs 10 + 8 = 18 bytes: the last line needs no padding.
        assert!(unpack(FOURCC_Y16, &[0; 18], 4, 2, 10).is_ok());
        let e = unpack(FOURCC_Y16, &[0; 17], 4, 2, 10).unwrap_err();
        assert_eq!(
            e,
            UnpackError::ShortBuffer {
                format: V4l2Format::Y16,
                width: 4,
                height: 2,
                need_bytes: 18,
                got_bytes: 17
            }
        );
        assert!(e.to_string().contains("17 bytes"), "{e}");
        for f in V4l2Format::ALL {
            let line = f.line_bytes(8).unwrap();
            let need = 2 * line + line;
            assert!(
                unpack(f.fourcc(), &vec![0; need], 8, 3, line).is_ok(),
                "{f}"
            );
            assert!(
                matches!(
                    unpack(f.fourcc(), &vec![0; need - 1], 8, 3, line),
                    Err(UnpackError::ShortBuffer { .. })
                ),
                "{f}"
            );
            assert!(
                matches!(
                    unpack(f.fourcc(), &[], 8, 3, line),
                    Err(UnpackError::ShortBuffer { .. })
                ),
                "{f}"
            );
        }
    }

    #[test]
    fn bad_strides_formats_and_sizes_are_errors() {
        assert!(matches!(
            unpack(FOURCC_Y10P, &[0; 64], 8, 2, 9),
            Err(UnpackError::StrideTooShort { line_bytes: 10, .. })
        ));
        let e = unpack(u32::from_le_bytes(*b"YUYV"), &[0; 64], 4, 4, 8).unwrap_err();
        assert!(e.to_string().contains("YUYV"), "{e}");
        assert!(matches!(
            unpack(FOURCC_Y16, &[0; 64], usize::MAX, 2, usize::MAX),
            Err(UnpackError::TooLarge { .. })
        ));
        assert!(matches!(
            unpack(FOURCC_GREY, &[0; 64], 8, usize::MAX, 8),
            Err(UnpackError::TooLarge { .. })
        ));
        assert_eq!(
            unpack(FOURCC_GREY, &[], 0, 0, 0).unwrap(),
            Vec::<u16>::new()
        );
    }
}
