//! The monochrome V4L2 pixel formats this driver decodes, their FourCCs and line sizes.
//!
//! Layouts follow the V4L2 UAPI, section "Image Formats → YUV Formats → Luma-Only Formats"
//! (`pixfmt-yuv-luma`): GREY is one byte per pixel; Y10, Y12 and Y16 are 16-bit little-endian
//! words with the sample in the low bits; Y10P and Y12P are the MIPI CSI-2 RAW10/RAW12 packings.

use ffdic_hw::PixelFormat;
use serde::{Deserialize, Serialize};
use std::fmt;

/// `v4l2_fourcc(a, b, c, d)`: the four characters little-endian in a u32 (videodev2.h).
const fn fourcc(code: &[u8; 4]) -> u32 {
    u32::from_le_bytes(*code)
}

pub const FOURCC_GREY: u32 = fourcc(b"GREY");
pub const FOURCC_Y10: u32 = fourcc(b"Y10 ");
pub const FOURCC_Y12: u32 = fourcc(b"Y12 ");
pub const FOURCC_Y16: u32 = fourcc(b"Y16 ");
pub const FOURCC_Y10P: u32 = fourcc(b"Y10P");
pub const FOURCC_Y12P: u32 = fourcc(b"Y12P");

/// A V4L2 luma-only format this driver can turn into 16-bit samples. In a config file it is
/// written as its FourCC without padding: "GREY", "Y10", "Y12", "Y16", "Y10P", "Y12P".
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum V4l2Format {
    #[serde(rename = "GREY")]
    Grey,
    #[serde(rename = "Y10")]
    Y10,
    #[serde(rename = "Y12")]
    Y12,
    #[serde(rename = "Y16")]
    Y16,
    /// MIPI RAW10: 4 pixels in 5 bytes.
    #[serde(rename = "Y10P")]
    Y10P,
    /// MIPI RAW12: 2 pixels in 3 bytes.
    #[serde(rename = "Y12P")]
    Y12P,
}

impl V4l2Format {
    pub const ALL: [V4l2Format; 6] = [
        V4l2Format::Grey,
        V4l2Format::Y10,
        V4l2Format::Y12,
        V4l2Format::Y16,
        V4l2Format::Y10P,
        V4l2Format::Y12P,
    ];

    pub fn fourcc(self) -> u32 {
        match self {
            V4l2Format::Grey => FOURCC_GREY,
            V4l2Format::Y10 => FOURCC_Y10,
            V4l2Format::Y12 => FOURCC_Y12,
            V4l2Format::Y16 => FOURCC_Y16,
            V4l2Format::Y10P => FOURCC_Y10P,
            V4l2Format::Y12P => FOURCC_Y12P,
        }
    }

    /// The format of a FourCC, if this driver decodes it.
    pub fn from_fourcc(code: u32) -> Option<Self> {
        Self::ALL.into_iter().find(|f| f.fourcc() == code)
    }

    pub fn pixel_format(self) -> PixelFormat {
        match self {
            V4l2Format::Grey => PixelFormat::Mono8,
            V4l2Format::Y10 | V4l2Format::Y10P => PixelFormat::Mono10,
            V4l2Format::Y12 | V4l2Format::Y12P => PixelFormat::Mono12,
            V4l2Format::Y16 => PixelFormat::Mono16,
        }
    }

    /// Significant bits per sample.
    pub fn bit_depth(self) -> u8 {
        self.pixel_format().bit_depth()
    }

    pub fn is_packed(self) -> bool {
        matches!(self, V4l2Format::Y10P | V4l2Format::Y12P)
    }

    /// Bytes one line of `width` pixels needs, without padding, or `None` on overflow. Packed
    /// formats count whole groups: a line whose width is not a multiple of the group still
    /// carries the group's shared low-bits byte (MIPI CSI-2 packs whole groups).
    pub fn line_bytes(self, width: usize) -> Option<usize> {
        match self {
            V4l2Format::Grey => Some(width),
            V4l2Format::Y10 | V4l2Format::Y12 | V4l2Format::Y16 => width.checked_mul(2),
            V4l2Format::Y10P => width.div_ceil(4).checked_mul(5),
            V4l2Format::Y12P => width.div_ceil(2).checked_mul(3),
        }
    }

    /// Bytes an image needs when lines start `bytes_per_line` apart. The last line needs no
    /// padding after it: drivers may end the buffer right after its last pixel.
    pub fn image_bytes(self, width: usize, height: usize, bytes_per_line: usize) -> Option<usize> {
        if width == 0 || height == 0 {
            return Some(0);
        }
        let line = self.line_bytes(width)?;
        (height - 1).checked_mul(bytes_per_line)?.checked_add(line)
    }

    /// The format to ask the device for when the caller wants `wanted`: the configured
    /// preference if it gives that depth and the device offers it, then the unpacked format
    /// (cheaper to decode, and what most drivers default to), then the packed one.
    pub fn choose(
        wanted: PixelFormat,
        offered: &[V4l2Format],
        preferred: Option<V4l2Format>,
    ) -> Option<V4l2Format> {
        let fits = |f: &V4l2Format| f.pixel_format() == wanted && offered.contains(f);
        preferred
            .into_iter()
            .chain(Self::ALL.into_iter().filter(|f| !f.is_packed()))
            .chain(Self::ALL.into_iter().filter(|f| f.is_packed()))
            .find(fits)
    }
}

impl fmt::Display for V4l2Format {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            V4l2Format::Grey => "GREY",
            V4l2Format::Y10 => "Y10",
            V4l2Format::Y12 => "Y12",
            V4l2Format::Y16 => "Y16",
            V4l2Format::Y10P => "Y10P",
            V4l2Format::Y12P => "Y12P",
        })
    }
}

/// A FourCC as its four characters, for messages about formats this driver does not decode.
pub fn fourcc_name(code: u32) -> String {
    code.to_le_bytes()
        .iter()
        .map(|&b| {
            if b.is_ascii_graphic() || b == b' ' {
                b as char
            } else {
                '?'
            }
        })
        .collect::<String>()
        .trim_end()
        .to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fourccs_are_the_videodev2_values() {
        assert_eq!(FOURCC_GREY, 0x5945_5247);
        assert_eq!(FOURCC_Y10, 0x2030_3159);
        assert_eq!(FOURCC_Y12, 0x2032_3159);
        assert_eq!(FOURCC_Y16, 0x2036_3159);
        assert_eq!(FOURCC_Y10P, 0x5030_3159);
        assert_eq!(FOURCC_Y12P, 0x5032_3159);
        for f in V4l2Format::ALL {
            assert_eq!(V4l2Format::from_fourcc(f.fourcc()), Some(f));
            assert_eq!(fourcc_name(f.fourcc()), f.to_string());
        }
        assert_eq!(V4l2Format::from_fourcc(fourcc(b"YUYV")), None);
        assert_eq!(fourcc_name(fourcc(b"MJPG")), "MJPG");
    }

    #[test]
    fn depths_map_to_hw_pixel_formats() {
        assert_eq!(V4l2Format::Grey.pixel_format(), PixelFormat::Mono8);
        assert_eq!(V4l2Format::Y10P.pixel_format(), PixelFormat::Mono10);
        assert_eq!(V4l2Format::Y12P.bit_depth(), 12);
        assert_eq!(V4l2Format::Y16.bit_depth(), 16);
    }

    #[test]
    fn line_bytes_count_whole_packed_groups() {
        assert_eq!(V4l2Format::Grey.line_bytes(7), Some(7));
        assert_eq!(V4l2Format::Y12.line_bytes(7), Some(14));
        assert_eq!(V4l2Format::Y10P.line_bytes(8), Some(10));
        assert_eq!(V4l2Format::Y10P.line_bytes(6), Some(10));
        assert_eq!(V4l2Format::Y12P.line_bytes(5), Some(9));
        assert_eq!(V4l2Format::Y16.line_bytes(usize::MAX), None);
        // 3 lines at stride 16, the last one unpadded.
        assert_eq!(V4l2Format::Y16.image_bytes(4, 3, 16), Some(40));
        assert_eq!(V4l2Format::Y16.image_bytes(0, 3, 16), Some(0));
        assert_eq!(V4l2Format::Y16.image_bytes(4, usize::MAX, 16), None);
    }

    #[test]
    fn choice_prefers_the_config_then_unpacked() {
        let offered = [V4l2Format::Y10P, V4l2Format::Y10, V4l2Format::Grey];
        let m10 = PixelFormat::Mono10;
        assert_eq!(
            V4l2Format::choose(m10, &offered, None),
            Some(V4l2Format::Y10)
        );
        assert_eq!(
            V4l2Format::choose(m10, &offered, Some(V4l2Format::Y10P)),
            Some(V4l2Format::Y10P)
        );
        // A preference of another depth does not override what the caller asked for.
        assert_eq!(
            V4l2Format::choose(m10, &offered, Some(V4l2Format::Grey)),
            Some(V4l2Format::Y10)
        );
        assert_eq!(
            V4l2Format::choose(m10, &[V4l2Format::Y10P], None),
            Some(V4l2Format::Y10P)
        );
        assert_eq!(
            V4l2Format::choose(PixelFormat::Mono16, &offered, None),
            None
        );
    }
}
