//! `ffdic-stage-sim --protocol smc100|zaber|apt [--speed-mm-s 5] [--travel-mm 25] [--y]`
//!
//! Serves a simulated stage controller on a pseudo-terminal until Ctrl-C. The first line on
//! stdout is the device path; stderr shows a `[stage]` config that points the daemon at it.

use ffdic_mocks::{SimConfig, SimProtocol, StageSim};
use std::process::ExitCode;

const USAGE: &str = "usage: ffdic-stage-sim --protocol smc100|zaber|apt [--speed-mm-s 5] \
                     [--travel-mm 25] [--y]";

#[derive(Debug)]
struct Args {
    protocol: SimProtocol,
    speed_mm_per_s: f64,
    travel_mm: f64,
    two_axes: bool,
}

fn parse_args(mut args: impl Iterator<Item = String>) -> Result<Args, String> {
    let mut protocol = None;
    let mut speed_mm_per_s = 5.0;
    let mut travel_mm = 25.0;
    let mut two_axes = false;
    while let Some(flag) = args.next() {
        let mut value = |name: &str| args.next().ok_or(format!("{name} needs a value"));
        match flag.as_str() {
            "--protocol" => {
                let v = value("--protocol")?;
                protocol = Some(SimProtocol::parse(&v).ok_or(format!("unknown protocol {v:?}"))?);
            }
            "--speed-mm-s" => speed_mm_per_s = positive("--speed-mm-s", &value("--speed-mm-s")?)?,
            "--travel-mm" => travel_mm = positive("--travel-mm", &value("--travel-mm")?)?,
            "--y" => two_axes = true,
            "-h" | "--help" => return Err(USAGE.into()),
            other => return Err(format!("unexpected argument {other:?}\n{USAGE}")),
        }
    }
    Ok(Args {
        protocol: protocol.ok_or(format!("--protocol is required\n{USAGE}"))?,
        speed_mm_per_s,
        travel_mm,
        two_axes,
    })
}

fn positive(name: &str, v: &str) -> Result<f64, String> {
    match v.parse::<f64>() {
        Ok(x) if x > 0.0 && x.is_finite() => Ok(x),
        _ => Err(format!("{name} must be a positive number, got {v:?}")),
    }
}

fn main() -> ExitCode {
    let args = match parse_args(std::env::args().skip(1)) {
        Ok(a) => a,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::from(2);
        }
    };
    let mut config = SimConfig::new(args.protocol);
    config.speed_mm_per_s = args.speed_mm_per_s;
    // Newport stages travel either side of a central home; Zaber and Thorlabs ones from home.
    let travel = match args.protocol {
        SimProtocol::Smc100 => (-args.travel_mm / 2.0, args.travel_mm / 2.0),
        SimProtocol::Zaber | SimProtocol::Apt => (0.0, args.travel_mm),
    };
    config.x_travel_mm = travel;
    if args.two_axes {
        config.y_travel_mm = Some(travel);
        if args.protocol == SimProtocol::Apt {
            // Two channels are two bays of a benchtop controller.
            (config.x_address, config.y_address) = (0x21, 0x22);
        }
    }
    let sim = match StageSim::spawn(config.clone(), None) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("cannot open a pseudo-terminal: {e}");
            return ExitCode::FAILURE;
        }
    };
    println!("{}", sim.path());
    let name = match args.protocol {
        SimProtocol::Smc100 => "smc100",
        SimProtocol::Zaber => "zaber",
        SimProtocol::Apt => "apt",
    };
    eprintln!("[stage]\nprotocol = \"{name}\"\nport = \"{}\"", sim.path());
    eprintln!("x_travel_mm = [{}, {}]", travel.0, travel.1);
    if args.two_axes {
        eprintln!(
            "x_address = {}\ny_address = {}",
            config.x_address, config.y_address
        );
        eprintln!("y_travel_mm = [{}, {}]", travel.0, travel.1);
    }
    eprintln!("# serving until Ctrl-C");
    loop {
        std::thread::park();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(line: &str) -> Result<Args, String> {
        parse_args(line.split_whitespace().map(String::from))
    }

    #[test]
    fn arguments() {
        let a = parse("--protocol zaber --speed-mm-s 12.5 --y").unwrap();
        assert_eq!(a.protocol, SimProtocol::Zaber);
        assert_eq!(
            (a.speed_mm_per_s, a.travel_mm, a.two_axes),
            (12.5, 25.0, true)
        );
        assert!(parse("--speed-mm-s 5").unwrap_err().contains("--protocol"));
        assert!(parse("--protocol esp").is_err());
        assert!(parse("--protocol apt --travel-mm -1").is_err());
        assert!(parse("--protocol apt --travel-mm").is_err());
    }
}
