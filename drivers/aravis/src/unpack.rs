//! Monochrome pixel data from GenICam buffers into 16-bit samples.
//!
//! `aravis::Buffer::into_image()` knows Mono8, RGB8 and Bayer only, so the formats a measurement
//! camera delivers (Mono10/12/16 in 16-bit little-endian containers, PFNC "unpacked") are decoded
//! here, as pure functions over bytes. Lines may carry padding: GVSP's `padding_x` is the number of
//! extra bytes at the end of every line, so the stride is `width · bytes_per_pixel + padding_x`.

use ffdic_hw::PixelFormat;

/// PFNC codes (GenICam Pixel Format Naming Convention 2.x) of the formats this driver decodes.
pub const PFNC_MONO8: u32 = 0x0108_0001;
pub const PFNC_MONO10: u32 = 0x0110_0003;
pub const PFNC_MONO12: u32 = 0x0110_0005;
pub const PFNC_MONO16: u32 = 0x0110_0007;

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum UnpackError {
    #[error("pixel format 0x{0:08x} is not Mono8/10/12/16")]
    UnsupportedFormat(u32),
    #[error("stride of {stride_bytes} bytes is shorter than a line of {line_bytes} bytes")]
    StrideTooShort {
        stride_bytes: usize,
        line_bytes: usize,
    },
    #[error("{got_bytes} bytes hold less than a {width}x{height} image ({need_bytes} bytes)")]
    ShortBuffer {
        width: usize,
        height: usize,
        need_bytes: usize,
        got_bytes: usize,
    },
}

/// The PFNC code of a format.
pub fn pfnc_code(format: PixelFormat) -> u32 {
    match format {
        PixelFormat::Mono8 => PFNC_MONO8,
        PixelFormat::Mono10 => PFNC_MONO10,
        PixelFormat::Mono12 => PFNC_MONO12,
        PixelFormat::Mono16 => PFNC_MONO16,
    }
}

/// The format of a PFNC code, if it is one this driver decodes.
pub fn from_pfnc(code: u32) -> Option<PixelFormat> {
    match code {
        PFNC_MONO8 => Some(PixelFormat::Mono8),
        PFNC_MONO10 => Some(PixelFormat::Mono10),
        PFNC_MONO12 => Some(PixelFormat::Mono12),
        PFNC_MONO16 => Some(PixelFormat::Mono16),
        _ => None,
    }
}

/// The GenICam `PixelFormat` enumeration entry of a format.
pub fn genicam_name(format: PixelFormat) -> &'static str {
    match format {
        PixelFormat::Mono8 => "Mono8",
        PixelFormat::Mono10 => "Mono10",
        PixelFormat::Mono12 => "Mono12",
        PixelFormat::Mono16 => "Mono16",
    }
}

/// The format of a GenICam `PixelFormat` entry name, if it is one this driver decodes.
pub fn from_genicam_name(name: &str) -> Option<PixelFormat> {
    match name {
        "Mono8" => Some(PixelFormat::Mono8),
        "Mono10" => Some(PixelFormat::Mono10),
        "Mono12" => Some(PixelFormat::Mono12),
        "Mono16" => Some(PixelFormat::Mono16),
        _ => None,
    }
}

/// Bytes one sample occupies in the buffer (10 and 12 bits sit in 16-bit containers).
pub fn bytes_per_pixel(format: PixelFormat) -> usize {
    match format {
        PixelFormat::Mono8 => 1,
        PixelFormat::Mono10 | PixelFormat::Mono12 | PixelFormat::Mono16 => 2,
    }
}

/// Decodes a `width x height` image whose lines start every `stride_bytes` bytes. The last line
/// needs no padding after it (GVSP may omit it). Values keep their bit depth: a Mono12 sample of
/// 4095 stays 4095.
pub fn unpack_mono(
    bytes: &[u8],
    width: usize,
    height: usize,
    format: PixelFormat,
    stride_bytes: usize,
) -> Result<Vec<u16>, UnpackError> {
    let bpp = bytes_per_pixel(format);
    let line_bytes = width * bpp;
    if stride_bytes < line_bytes {
        return Err(UnpackError::StrideTooShort {
            stride_bytes,
            line_bytes,
        });
    }
    let need_bytes = match height {
        0 => 0,
        h => (h - 1) * stride_bytes + line_bytes,
    };
    if bytes.len() < need_bytes {
        return Err(UnpackError::ShortBuffer {
            width,
            height,
            need_bytes,
            got_bytes: bytes.len(),
        });
    }
    let mut out = Vec::with_capacity(width * height);
    for row in 0..height {
        let line = &bytes[row * stride_bytes..row * stride_bytes + line_bytes];
        match bpp {
            1 => out.extend(line.iter().map(|&b| b as u16)),
            _ => out.extend(
                line.chunks_exact(2)
                    .map(|pair| u16::from_le_bytes([pair[0], pair[1]])),
            ),
        }
    }
    Ok(out)
}

/// Encodes 16-bit samples as a Mono8 or Mono16 payload (what the fake camera sends): Mono16 as
/// little-endian words, Mono8 as the top byte of each sample.
pub fn pack_for_fake(samples: &[u16], pfnc: u32, out: &mut [u8]) -> Result<(), UnpackError> {
    match pfnc {
        PFNC_MONO16 => {
            for (dst, &v) in out.chunks_exact_mut(2).zip(samples) {
                dst.copy_from_slice(&v.to_le_bytes());
            }
            Ok(())
        }
        PFNC_MONO8 => {
            for (dst, &v) in out.iter_mut().zip(samples) {
                *dst = (v >> 8) as u8;
            }
            Ok(())
        }
        other => Err(UnpackError::UnsupportedFormat(other)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mono8_without_padding() {
        let bytes = [0u8, 1, 254, 255, 7, 8];
        let v = unpack_mono(&bytes, 3, 2, PixelFormat::Mono8, 3).unwrap();
        assert_eq!(v, vec![0, 1, 254, 255, 7, 8]);
    }

    #[test]
    fn mono16_is_little_endian() {
        let bytes = [0x34, 0x12, 0xff, 0xff, 0x00, 0x80, 0x01, 0x00];
        let v = unpack_mono(&bytes, 2, 2, PixelFormat::Mono16, 4).unwrap();
        assert_eq!(v, vec![0x1234, 0xffff, 0x8000, 1]);
    }

    #[test]
    fn mono12_and_mono10_keep_their_values() {
        let bytes = [0xff, 0x0f, 0x00, 0x08];
        assert_eq!(
            unpack_mono(&bytes, 2, 1, PixelFormat::Mono12, 4).unwrap(),
            vec![4095, 2048]
        );
        let bytes = [0xff, 0x03, 0x01, 0x02];
        assert_eq!(
            unpack_mono(&bytes, 2, 1, PixelFormat::Mono10, 4).unwrap(),
            vec![1023, 513]
        );
    }

    #[test]
    fn padding_at_line_ends_is_skipped() {
        // 2x3 Mono16 with 3 padding bytes per line (stride 7); the last line has no padding.
        let mut bytes = Vec::new();
        for row in 0..3u16 {
            bytes.extend((row * 10).to_le_bytes());
            bytes.extend((row * 10 + 1).to_le_bytes());
            if row < 2 {
                bytes.extend([0xaa, 0xbb, 0xcc]);
            }
        }
        let v = unpack_mono(&bytes, 2, 3, PixelFormat::Mono16, 7).unwrap();
        assert_eq!(v, vec![0, 1, 10, 11, 20, 21]);
        let m8 = [1u8, 2, 9, 3, 4];
        assert_eq!(
            unpack_mono(&m8, 2, 2, PixelFormat::Mono8, 3).unwrap(),
            vec![1, 2, 3, 4]
        );
    }

    #[test]
    fn short_buffers_and_strides_are_errors() {
        assert_eq!(
            unpack_mono(&[0u8; 7], 2, 2, PixelFormat::Mono16, 4),
            Err(UnpackError::ShortBuffer {
                width: 2,
                height: 2,
                need_bytes: 8,
                got_bytes: 7
            })
        );
        assert!(matches!(
            unpack_mono(&[0u8; 8], 2, 2, PixelFormat::Mono16, 3),
            Err(UnpackError::StrideTooShort { .. })
        ));
        assert_eq!(
            unpack_mono(&[], 5, 0, PixelFormat::Mono8, 5).unwrap(),
            vec![]
        );
    }

    #[test]
    fn codes_and_names_round_trip() {
        for f in [
            PixelFormat::Mono8,
            PixelFormat::Mono10,
            PixelFormat::Mono12,
            PixelFormat::Mono16,
        ] {
            assert_eq!(from_pfnc(pfnc_code(f)), Some(f));
            assert_eq!(from_genicam_name(genicam_name(f)), Some(f));
        }
        assert_eq!(from_pfnc(0x0108_0009), None); // BayerRG8
        assert_eq!(from_genicam_name("RGB8"), None);
    }

    #[test]
    fn packing_for_the_fake_camera_inverts_unpacking() {
        let samples = [0u16, 1, 0x1234, 0xffff];
        let mut b16 = [0u8; 8];
        pack_for_fake(&samples, PFNC_MONO16, &mut b16).unwrap();
        assert_eq!(
            unpack_mono(&b16, 4, 1, PixelFormat::Mono16, 8).unwrap(),
            samples
        );
        let mut b8 = [0u8; 4];
        pack_for_fake(&samples, PFNC_MONO8, &mut b8).unwrap();
        assert_eq!(b8, [0, 0, 0x12, 0xff]);
        assert_eq!(
            pack_for_fake(&samples, PFNC_MONO12, &mut b16),
            Err(UnpackError::UnsupportedFormat(PFNC_MONO12))
        );
    }
}
