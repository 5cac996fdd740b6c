//! Newport SMC100 / CONEX-CC command syntax, as pure functions. References are to the SMC100CC/PP
//! user's manual, section 2 ("Remote mode: command set"): a command is `<address><two letters>
//! [?|value]` ended by CR LF, and a query reply repeats address and command before the value.

use ffdic_hw::{HwError, HwResult};

/// Positioner error bits of `TS` (manual 2.2, "TS — Get positioner error and controller state").
pub const NEGATIVE_END_OF_RUN: u16 = 0x0001;
pub const POSITIVE_END_OF_RUN: u16 = 0x0002;
const ERROR_BITS: [(u16, &str); 10] = [
    (0x0001, "negative end of run"),
    (0x0002, "positive end of run"),
    (0x0004, "peak current limit"),
    (0x0008, "RMS current limit"),
    (0x0010, "short circuit detection"),
    (0x0020, "following error"),
    (0x0040, "homing time out"),
    (0x0080, "wrong ESP stage"),
    (0x0100, "DC voltage too low"),
    (0x0200, "80 W output power exceeded"),
];

/// The controller state byte of `TS`, grouped as the driver needs it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ControllerState {
    /// 0A–11: power-up or after an abort; moves are refused until `OR`.
    NotReferenced,
    /// 14.
    Configuration,
    /// 1E (commanded over RS-232), 1F (by the SMC-RC remote).
    Homing,
    /// 28 (includes settling into the in-position window).
    Moving,
    /// 32–35.
    Ready,
    /// 3C–3E.
    Disabled,
    /// 46–47.
    Jogging,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ControllerStatus {
    pub error_bits: u16,
    /// The raw state code, for messages.
    pub code: u8,
    pub state: ControllerState,
}

/// `1TS\r\n`: a command without a value.
pub fn command(address: u8, mnemonic: &str) -> String {
    format!("{address}{mnemonic}\r\n")
}

/// The last decimal [`command_mm`] writes, mm: the finest step this driver commands.
pub const RESOLUTION_MM: f64 = 1e-6;

/// `1PA5.250000\r\n`: a command with a value in mm, to 1 nm (the controller's own resolution is
/// coarser; fixed notation because the controller does not read exponents).
pub fn command_mm(address: u8, mnemonic: &str, value_mm: f64) -> String {
    format!("{address}{mnemonic}{value_mm:.6}\r\n")
}

/// The value part of a reply `1TP5.25` (or `1TP?5.25`) to `mnemonic` from `address`.
pub fn reply_value<'a>(line: &'a str, address: u8, mnemonic: &str) -> HwResult<&'a str> {
    let prefix = format!("{address}{mnemonic}");
    line.trim()
        .strip_prefix(prefix.as_str())
        .map(|v| v.strip_prefix('?').unwrap_or(v))
        .ok_or_else(|| {
            HwError::Protocol(format!(
                "expected a reply starting {prefix:?} from SMC100 address {address}, got {line:?}"
            ))
        })
}

/// `000033` → error bits 0x0000, state 0x33 (READY from MOVING).
pub fn parse_status(value: &str) -> HwResult<ControllerStatus> {
    let bad = || HwError::Protocol(format!("TS value {value:?} is not 4+2 hex digits"));
    if value.len() != 6 || !value.bytes().all(|b| b.is_ascii_hexdigit()) {
        return Err(bad());
    }
    let error_bits = u16::from_str_radix(&value[..4], 16).map_err(|_| bad())?;
    let code = u8::from_str_radix(&value[4..], 16).map_err(|_| bad())?;
    let state = match code {
        0x0A..=0x11 => ControllerState::NotReferenced,
        0x14 => ControllerState::Configuration,
        0x1E | 0x1F => ControllerState::Homing,
        0x28 => ControllerState::Moving,
        0x32..=0x35 => ControllerState::Ready,
        0x3C..=0x3E => ControllerState::Disabled,
        0x46 | 0x47 => ControllerState::Jogging,
        _ => {
            return Err(HwError::Protocol(format!(
                "TS state code 0x{code:02X} is not an SMC100 state"
            )))
        }
    };
    Ok(ControllerStatus {
        error_bits,
        code,
        state,
    })
}

/// A position or limit value, mm.
pub fn parse_mm(value: &str) -> HwResult<f64> {
    value
        .trim()
        .parse::<f64>()
        .ok()
        .filter(|v| v.is_finite())
        .ok_or_else(|| HwError::Protocol(format!("{value:?} is not a position in mm")))
}

/// The error letter of a `TE` reply; `@` means none.
pub fn parse_error_letter(value: &str) -> HwResult<char> {
    let mut chars = value.trim().chars();
    match (chars.next(), chars.next()) {
        (Some(c), None) if c == '@' || c.is_ascii_uppercase() => Ok(c),
        _ => Err(HwError::Protocol(format!(
            "TE value {value:?} is not an error letter"
        ))),
    }
}

/// What a `TE` letter means (manual 2.2, "TE — Get command error string").
pub fn error_message(letter: char) -> &'static str {
    match letter {
        '@' => "no error",
        'A' => "unknown message code or floating point controller address",
        'B' => "controller address not correct",
        'C' => "parameter missing or out of range",
        'D' => "command not allowed",
        'E' => "home sequence already started",
        'G' => "displacement out of limits",
        'H' => "command not allowed in NOT REFERENCED state",
        'I' => "command not allowed in CONFIGURATION state",
        'J' => "command not allowed in DISABLE state",
        'K' => "command not allowed in READY state",
        'L' => "command not allowed in HOMING state",
        'M' => "command not allowed in MOVING state",
        'N' => "current position out of software limit",
        'S' => "communication time out",
        'U' => "error during EEPROM access",
        'V' => "error during command execution",
        'W' => "command not allowed for PP version",
        'X' => "command not allowed for CC version",
        _ => "undocumented error",
    }
}

/// The names of the positioner error bits set in `bits`, comma-separated.
pub fn describe_error_bits(bits: u16) -> String {
    let names: Vec<&str> = ERROR_BITS
        .iter()
        .filter(|(bit, _)| bits & bit != 0)
        .map(|(_, name)| *name)
        .collect();
    if names.is_empty() {
        format!("unknown error bits 0x{bits:04X}")
    } else {
        names.join(", ")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commands_carry_address_and_crlf() {
        assert_eq!(command(1, "OR"), "1OR\r\n");
        assert_eq!(command(12, "TS"), "12TS\r\n");
        assert_eq!(command_mm(2, "PA", 5.25), "2PA5.250000\r\n");
        assert_eq!(command_mm(1, "PR", -0.0005), "1PR-0.000500\r\n");
    }

    #[test]
    fn ts_reply_in_both_forms() {
        for line in ["1TS000033", "1TS?000033", "1TS000033 "] {
            let s = parse_status(reply_value(line, 1, "TS").unwrap()).unwrap();
            assert_eq!(s.state, ControllerState::Ready);
            assert_eq!(s.error_bits, 0);
            assert_eq!(s.code, 0x33);
        }
        let s = parse_status(reply_value("2TS00020A", 2, "TS").unwrap()).unwrap();
        assert_eq!(s.state, ControllerState::NotReferenced);
        assert_eq!(s.error_bits, POSITIVE_END_OF_RUN);
        assert_eq!(describe_error_bits(s.error_bits), "positive end of run");
        for (code, state) in [
            ("1E", ControllerState::Homing),
            ("28", ControllerState::Moving),
            ("3D", ControllerState::Disabled),
            ("14", ControllerState::Configuration),
            ("47", ControllerState::Jogging),
        ] {
            assert_eq!(parse_status(&format!("0000{code}")).unwrap().state, state);
        }
    }

    #[test]
    fn malformed_replies_are_protocol_errors() {
        assert!(matches!(
            reply_value("2TS000033", 1, "TS"),
            Err(HwError::Protocol(_))
        ));
        assert!(reply_value("1TP5.25", 1, "TS").is_err());
        for v in ["00033", "0000333", "00G033", "000099", ""] {
            assert!(matches!(parse_status(v), Err(HwError::Protocol(_))), "{v}");
        }
        assert!(parse_mm("5.2.5").is_err());
        assert!(parse_mm("NaN").is_err());
        assert!(parse_error_letter("AB").is_err());
    }

    #[test]
    fn tp_and_te_values() {
        assert_eq!(
            parse_mm(reply_value("1TP5.25", 1, "TP").unwrap()).unwrap(),
            5.25
        );
        assert_eq!(parse_mm("-0.0001").unwrap(), -0.0001);
        assert_eq!(parse_error_letter("@").unwrap(), '@');
        assert_eq!(
            error_message(parse_error_letter("H").unwrap()),
            "command not allowed in NOT REFERENCED state"
        );
    }
}
