//! A quick-look PNG of a 16-bit frame: 8-bit, stretched between the 0.5th and 99.5th percentiles
//! so the speckle is visible whatever the exposure. For people, not for measurement (the TIFF is).

/// Encodes `data` (row-major, `width x height`) as an 8-bit grey PNG.
pub fn png_quicklook(width: usize, height: usize, data: &[u16]) -> Result<Vec<u8>, String> {
    if data.len() != width * height || data.is_empty() {
        return Err(format!(
            "{} samples for a {width}x{height} image",
            data.len()
        ));
    }
    let (lo, hi) = percentiles(data, 0.005, 0.995);
    let span = (hi - lo).max(1) as f32;
    let pixels: Vec<u8> = data
        .iter()
        .map(|&v| ((v.saturating_sub(lo)) as f32 / span * 255.0).clamp(0.0, 255.0) as u8)
        .collect();
    let mut out = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut out, width as u32, height as u32);
        encoder.set_color(png::ColorType::Grayscale);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header().map_err(|e| e.to_string())?;
        writer
            .write_image_data(&pixels)
            .map_err(|e| e.to_string())?;
    }
    Ok(out)
}

/// Two quantiles of 16-bit data from a histogram (one pass, no sort).
fn percentiles(data: &[u16], lo_q: f64, hi_q: f64) -> (u16, u16) {
    let mut hist = vec![0u64; 65536];
    for &v in data {
        hist[v as usize] += 1;
    }
    let n = data.len() as f64;
    let quantile = |q: f64| {
        let target = (q * n) as u64;
        let mut seen = 0u64;
        for (value, &count) in hist.iter().enumerate() {
            seen += count;
            if seen > target {
                return value as u16;
            }
        }
        u16::MAX
    };
    (quantile(lo_q), quantile(hi_q))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn encodes_a_png_and_stretches() {
        let data: Vec<u16> = (0..64u16).map(|v| 1000 + v * 10).collect();
        let bytes = png_quicklook(8, 8, &data).unwrap();
        assert_eq!(&bytes[1..4], b"PNG");
        let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
        let mut reader = decoder.read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size()];
        reader.next_frame(&mut buf).unwrap();
        assert_eq!(buf[0], 0);
        assert!(buf[63] >= 250, "{}", buf[63]);
        assert!(png_quicklook(8, 7, &data).is_err());
    }
}
