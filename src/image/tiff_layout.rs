//! The two grey layouts the `tiff` crate refuses — palette (PhotometricInterpretation 3, as DIC
//! Challenge Sample 12 is distributed) and grey with an alpha sample — made readable by
//! rewriting a few fields of the first IFD in a copy of the file, so the crate decodes the
//! samples as plain grey: palette indices (mapped through the ColorMap afterwards), or grey
//! and alpha interleaved as one row twice as wide (alpha dropped afterwards).
//!
//! Only classic TIFF (not BigTIFF) and only the first page; grey+alpha with a horizontal
//! predictor is refused (the predictor would difference across the interleaved samples).

const TAG_IMAGE_WIDTH: u16 = 256;
const TAG_BITS_PER_SAMPLE: u16 = 258;
const TAG_PHOTOMETRIC: u16 = 262;
const TAG_SAMPLES_PER_PIXEL: u16 = 277;
const TAG_PREDICTOR: u16 = 317;
const PHOTOMETRIC_MIN_IS_BLACK: u32 = 1;
const PHOTOMETRIC_PALETTE: u32 = 3;
const TYPE_SHORT: u16 = 3;
const TYPE_LONG: u16 = 4;

/// What the rewrite made of the file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Rewritten {
    /// Decode as grey: the values are palette indices.
    Palette(Vec<u8>),
    /// Decode as grey: every row holds grey and alpha interleaved; keep the even samples.
    GreyAlpha(Vec<u8>),
}

struct Entry {
    /// Byte offset of the 12-byte entry.
    at: usize,
    tag: u16,
    kind: u16,
    count: u32,
}

struct Ifd {
    little: bool,
    entries: Vec<Entry>,
}

impl Ifd {
    fn parse(bytes: &[u8]) -> Option<Self> {
        let little = match bytes.get(0..2)? {
            b"II" => true,
            b"MM" => false,
            _ => return None,
        };
        let ifd = Self {
            little,
            entries: Vec::new(),
        };
        if ifd.u16_at(bytes, 2)? != 42 {
            return None; // BigTIFF (43) or not a TIFF
        }
        let start = ifd.u32_at(bytes, 4)? as usize;
        let count = ifd.u16_at(bytes, start)? as usize;
        let mut entries = Vec::with_capacity(count);
        for k in 0..count {
            let at = start + 2 + 12 * k;
            entries.push(Entry {
                at,
                tag: ifd.u16_at(bytes, at)?,
                kind: ifd.u16_at(bytes, at + 2)?,
                count: ifd.u32_at(bytes, at + 4)?,
            });
        }
        Some(Self { entries, ..ifd })
    }

    fn u16_at(&self, b: &[u8], at: usize) -> Option<u16> {
        let v: [u8; 2] = b.get(at..at + 2)?.try_into().ok()?;
        Some(if self.little {
            u16::from_le_bytes(v)
        } else {
            u16::from_be_bytes(v)
        })
    }

    fn u32_at(&self, b: &[u8], at: usize) -> Option<u32> {
        let v: [u8; 4] = b.get(at..at + 4)?.try_into().ok()?;
        Some(if self.little {
            u32::from_le_bytes(v)
        } else {
            u32::from_be_bytes(v)
        })
    }

    fn entry(&self, tag: u16) -> Option<&Entry> {
        self.entries.iter().find(|e| e.tag == tag)
    }

    /// The first value of a SHORT or LONG entry stored in the entry itself.
    fn value(&self, b: &[u8], tag: u16) -> Option<u32> {
        let e = self.entry(tag)?;
        match e.kind {
            TYPE_SHORT => self.u16_at(b, e.at + 8).map(u32::from),
            TYPE_LONG => self.u32_at(b, e.at + 8),
            _ => None,
        }
    }

    fn set_value(&self, b: &mut [u8], tag: u16, value: u32) -> Option<()> {
        let e = self.entry(tag)?;
        match e.kind {
            TYPE_SHORT => {
                let v = u16::try_from(value).ok()?;
                let bytes = if self.little {
                    v.to_le_bytes()
                } else {
                    v.to_be_bytes()
                };
                b.get_mut(e.at + 8..e.at + 10)?.copy_from_slice(&bytes);
            }
            TYPE_LONG => {
                let bytes = if self.little {
                    value.to_le_bytes()
                } else {
                    value.to_be_bytes()
                };
                b.get_mut(e.at + 8..e.at + 12)?.copy_from_slice(&bytes);
            }
            _ => return None,
        }
        Some(())
    }

    fn set_count(&self, b: &mut [u8], tag: u16, count: u32) -> Option<()> {
        let e = self.entry(tag)?;
        let bytes = if self.little {
            count.to_le_bytes()
        } else {
            count.to_be_bytes()
        };
        b.get_mut(e.at + 4..e.at + 8)?.copy_from_slice(&bytes);
        Some(())
    }
}

/// A copy of `bytes` the `tiff` crate decodes as grey, for a palette or grey+alpha file; None
/// for any other layout (left to the crate and its own error).
pub fn rewrite_as_grey(bytes: &[u8]) -> Option<Rewritten> {
    let ifd = Ifd::parse(bytes)?;
    let photometric = ifd.value(bytes, TAG_PHOTOMETRIC)?;
    let samples = ifd.value(bytes, TAG_SAMPLES_PER_PIXEL).unwrap_or(1);
    let mut copy = bytes.to_vec();
    if photometric == PHOTOMETRIC_PALETTE && samples == 1 {
        ifd.set_value(&mut copy, TAG_PHOTOMETRIC, PHOTOMETRIC_MIN_IS_BLACK)?;
        return Some(Rewritten::Palette(copy));
    }
    let bits = ifd.entry(TAG_BITS_PER_SAMPLE)?;
    // Two SHORT bit depths fit in the entry itself: the first stays, the count becomes 1.
    let horizontal_predictor = ifd.value(bytes, TAG_PREDICTOR) == Some(2);
    if photometric == PHOTOMETRIC_MIN_IS_BLACK
        && samples == 2
        && bits.kind == TYPE_SHORT
        && bits.count == 2
        && !horizontal_predictor
    {
        let width = ifd.value(bytes, TAG_IMAGE_WIDTH)?;
        ifd.set_value(&mut copy, TAG_SAMPLES_PER_PIXEL, 1)?;
        ifd.set_count(&mut copy, TAG_BITS_PER_SAMPLE, 1)?;
        ifd.set_value(&mut copy, TAG_IMAGE_WIDTH, width.checked_mul(2)?)?;
        return Some(Rewritten::GreyAlpha(copy));
    }
    None
}
