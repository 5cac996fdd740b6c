//! `ffdic reduce IN.tif (--scheme ff100|ff50|ff25 | --block 3x3 --aperture 1x3 [--offset 1x0]) -o OUT.tif`

use anyhow::{Context, Result};
use clap::{ArgGroup, Args};
use ffdic::image::{read_image, write_tiff_u16};
use ffdic::reduce::{reduce, Scheme};
use std::path::PathBuf;

#[derive(Debug, Args)]
#[command(group(ArgGroup::new("how").required(true).args(["scheme", "block"])))]
pub struct ReduceArgs {
    /// Full-resolution grayscale TIFF.
    pub input: PathBuf,
    /// A preset: ff100 (2x2 binned), ff50 (rows binned, columns subsampled), ff25 (subsampled).
    #[arg(long)]
    pub scheme: Option<String>,
    /// Block of sensor pixels per reduced pixel, COLSxROWS (e.g. 3x3).
    #[arg(long, requires = "aperture")]
    pub block: Option<String>,
    /// Light-sensitive pixels in the block, COLSxROWS (e.g. 1x3); centred unless --offset.
    #[arg(long, requires = "block")]
    pub aperture: Option<String>,
    /// First active column and row inside the block, COLxROW.
    #[arg(long, requires = "block")]
    pub offset: Option<String>,
    /// Output 16-bit TIFF.
    #[arg(short, long)]
    pub output: PathBuf,
}

pub fn run(args: &ReduceArgs) -> Result<()> {
    let scheme = match (&args.scheme, &args.block, &args.aperture) {
        (Some(name), _, _) => Scheme::preset(name)?,
        (None, Some(block), Some(aperture)) => {
            Scheme::from_block(block, aperture, args.offset.as_deref())?
        }
        _ => anyhow::bail!("give --scheme, or --block with --aperture"),
    };
    let (image, _) = read_image(&args.input)?;
    let reduced = reduce(&image, &scheme)?;
    write_tiff_u16(&args.output, &reduced)
        .with_context(|| format!("writing {}", args.output.display()))?;
    let (fx, fy) = scheme.linear_fill_factor();
    let (ox, oy) = scheme.centre_offset_px();
    println!(
        "{}: {}x{} -> {}x{}, linear fill factor {:.0} % x {:.0} %, reduced pixel (0,0) centred at full-res ({ox}, {oy})",
        scheme.name,
        image.width(),
        image.height(),
        reduced.width(),
        reduced.height(),
        fx * 100.0,
        fy * 100.0
    );
    Ok(())
}
