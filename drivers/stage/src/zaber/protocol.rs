//! Zaber ASCII protocol messages, as pure functions (Zaber ASCII Protocol Manual, "Message
//! format"): commands `/<device> <axis> [id] <command> [:CC]\n`; replies `@<device> <axis> [id]
//! <OK|RJ> <IDLE|BUSY> <warning> <data>[:CC]\r\n`; info lines start `#`, alerts `!`.

use ffdic_hw::{HwError, HwResult};

/// A reply (`@…`) line, split into fields.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Reply {
    pub device: u8,
    pub axis: u8,
    /// The message id, when the command carried one.
    pub id: Option<u8>,
    /// `OK` (true) or `RJ` (false).
    pub ok: bool,
    /// `BUSY` (true) or `IDLE` (false).
    pub busy: bool,
    /// The highest-priority warning flag, `--` when there is none.
    pub warning: String,
    /// The rest: a value (`get pos`), `0`, or the reason of a rejection (`BADDATA`).
    pub data: String,
}

/// Any line a device sends.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Message {
    Reply(Reply),
    /// `#…`: extra lines of a reply (help text, some `get` results); not used by the driver.
    Info(String),
    /// `!…`: unprompted notices such as motion finished, when alerts are enabled.
    Alert(String),
}

/// What a warning flag means for the driver (manual, "Warning flags").
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WarningClass {
    None,
    /// `WR`: no reference position: home first.
    NotHomed,
    /// `WL` unexpected limit trigger, `FE` limit error.
    LimitSwitch,
    /// Any other `F…` flag (stall `FS`, encoder `FQ`, driver disabled `FD`, …): the move failed.
    Fault,
    /// `N…` notices and other `W…` warnings: informative only.
    Notice,
}

pub fn classify_warning(flag: &str) -> WarningClass {
    match flag {
        "--" => WarningClass::None,
        "WR" => WarningClass::NotHomed,
        "WL" | "FE" => WarningClass::LimitSwitch,
        f if f.starts_with('F') => WarningClass::Fault,
        _ => WarningClass::Notice,
    }
}

/// The longitudinal redundancy check over `content` (the bytes between the start character and
/// the colon): 256 − (sum of bytes mod 256), mod 256.
pub fn checksum(content: &[u8]) -> u8 {
    let sum = content.iter().fold(0u8, |s, &b| s.wrapping_add(b));
    sum.wrapping_neg()
}

/// `/1 1 7 move abs 1000:CS\n`; an empty `text` is the status poll `/1 1 7:CS\n`.
pub fn encode_command(
    device: u8,
    axis: u8,
    id: Option<u8>,
    text: &str,
    with_checksum: bool,
) -> String {
    let mut content = format!("{device} {axis}");
    if let Some(id) = id {
        content.push_str(&format!(" {id}"));
    }
    if !text.is_empty() {
        content.push(' ');
        content.push_str(text);
    }
    if with_checksum {
        format!("/{content}:{:02X}\n", checksum(content.as_bytes()))
    } else {
        format!("/{content}\n")
    }
}

/// Parses one received line (terminator already removed), checking its checksum if it has one.
pub fn parse_message(line: &str) -> HwResult<Message> {
    let bad = |why: &str| HwError::Protocol(format!("Zaber line {line:?}: {why}"));
    let mut chars = line.chars();
    let start = chars.next().ok_or_else(|| bad("empty"))?;
    let rest = chars.as_str();
    let content = match rest.rfind(':') {
        Some(colon) => {
            let (content, sum) = (&rest[..colon], &rest[colon + 1..]);
            let sum = u8::from_str_radix(sum.trim(), 16).map_err(|_| bad("bad checksum field"))?;
            if checksum(content.as_bytes()) != sum {
                return Err(bad("checksum mismatch"));
            }
            content
        }
        None => rest,
    };
    // A trailing `\` marks a continued packet; the driver never asks for long replies.
    let content = content.trim_end().trim_end_matches('\\').trim_end();
    match start {
        '@' => parse_reply_fields(content)
            .ok_or_else(|| bad("not a reply"))
            .map(Message::Reply),
        '#' => Ok(Message::Info(content.to_string())),
        '!' => Ok(Message::Alert(content.to_string())),
        _ => Err(bad("does not start with @, # or !")),
    }
}

fn parse_reply_fields(content: &str) -> Option<Reply> {
    let mut words = content.split_whitespace().peekable();
    let device = parse_digits(words.next()?)?;
    let axis = parse_digits(words.next()?)?;
    let id = match words.peek() {
        Some(w) if w.bytes().all(|b| b.is_ascii_digit()) => Some(parse_digits(words.next()?)?),
        _ => None,
    };
    let ok = match words.next()? {
        "OK" => true,
        "RJ" => false,
        _ => return None,
    };
    let busy = match words.next()? {
        "BUSY" => true,
        "IDLE" => false,
        _ => return None,
    };
    let warning = words.next()?;
    if warning.len() != 2 {
        return None;
    }
    let data: Vec<&str> = words.collect();
    Some(Reply {
        device,
        axis,
        id,
        ok,
        busy,
        warning: warning.to_string(),
        data: data.join(" "),
    })
}

fn parse_digits(word: &str) -> Option<u8> {
    if word.is_empty() || !word.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    word.parse().ok()
}

/// The integer value of a reply (`get pos` → microsteps).
pub fn parse_integer(reply: &Reply) -> HwResult<i64> {
    reply.data.trim().parse().map_err(|_| {
        HwError::Protocol(format!(
            "Zaber device {} axis {}: {:?} is not an integer",
            reply.device, reply.axis, reply.data
        ))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn checksum_is_the_twos_complement_of_the_byte_sum() {
        let content = b"01 1 OK IDLE -- 0";
        let sum: u32 = content.iter().map(|&b| b as u32).sum();
        assert_eq!(checksum(content) as u32, (256 - sum % 256) % 256);
        assert_eq!(checksum(b""), 0);
        // The sum of content and checksum is 0 mod 256.
        let cs = checksum(b"1 1 move abs 10000");
        let total = b"1 1 move abs 10000"
            .iter()
            .fold(cs, |s, &b| s.wrapping_add(b));
        assert_eq!(total, 0);
    }

    #[test]
    fn commands_with_and_without_id_and_checksum() {
        assert_eq!(
            encode_command(1, 1, None, "move abs 10000", false),
            "/1 1 move abs 10000\n"
        );
        assert_eq!(encode_command(2, 1, None, "", false), "/2 1\n");
        let line = encode_command(1, 1, Some(7), "get pos", true);
        let (content, sum) = line[1..line.len() - 1].split_once(':').unwrap();
        assert_eq!(content, "1 1 7 get pos");
        assert_eq!(
            u8::from_str_radix(sum, 16).unwrap(),
            checksum(content.as_bytes())
        );
    }

    #[test]
    fn replies_with_flags_ids_and_checksums() {
        let Message::Reply(r) = parse_message("@01 1 OK BUSY -- 0").unwrap() else {
            panic!()
        };
        assert_eq!(
            (r.device, r.axis, r.id, r.ok, r.busy),
            (1, 1, None, true, true)
        );
        assert_eq!((r.warning.as_str(), r.data.as_str()), ("--", "0"));

        let content = "02 1 42 RJ IDLE WR BADDATA";
        let line = format!("@{content}:{:02X}", checksum(content.as_bytes()));
        let Message::Reply(r) = parse_message(&line).unwrap() else {
            panic!()
        };
        assert_eq!((r.device, r.id, r.ok, r.busy), (2, Some(42), false, false));
        assert_eq!(classify_warning(&r.warning), WarningClass::NotHomed);
        assert_eq!(r.data, "BADDATA");

        let Message::Reply(r) = parse_message("@01 1 OK IDLE -- -12345").unwrap() else {
            panic!()
        };
        assert_eq!(parse_integer(&r).unwrap(), -12345);
        assert!(matches!(
            parse_message("!01 1 IDLE --").unwrap(),
            Message::Alert(_)
        ));
        assert!(matches!(
            parse_message("#01 1 0 help").unwrap(),
            Message::Info(_)
        ));
    }

    #[test]
    fn corrupt_lines_are_protocol_errors() {
        for line in [
            "@01 1 OK IDLE -- 0:00",
            "@01 1 OK IDLE -- 0:ZZ",
            "@01 1 MAYBE IDLE -- 0",
            "@01 1 OK RESTING -- 0",
            "@01 1 OK IDLE - 0",
            "@01",
            "01 1 OK IDLE -- 0",
            "",
        ] {
            assert!(
                matches!(parse_message(line), Err(HwError::Protocol(_))),
                "{line}"
            );
        }
        let Message::Reply(r) = parse_message("@01 1 OK IDLE -- 1.5x").unwrap() else {
            panic!()
        };
        assert!(parse_integer(&r).is_err());
    }

    #[test]
    fn warning_classes() {
        assert_eq!(classify_warning("--"), WarningClass::None);
        assert_eq!(classify_warning("WL"), WarningClass::LimitSwitch);
        assert_eq!(classify_warning("FS"), WarningClass::Fault);
        assert_eq!(classify_warning("FQ"), WarningClass::Fault);
        assert_eq!(classify_warning("NI"), WarningClass::Notice);
    }

    #[test]
    fn random_lines_never_panic() {
        let alphabet = b"@#!/:0123456789 OKRJIDLEBUSY-WRFS\\xA";
        let mut state = 0x9e37_79b9_7f4a_7c15_u64;
        for _ in 0..2_000 {
            let line: String = (0..(state % 30))
                .map(|_| {
                    state = state
                        .wrapping_mul(6_364_136_223_846_793_005)
                        .wrapping_add(1);
                    alphabet[(state >> 33) as usize % alphabet.len()] as char
                })
                .collect();
            if let Ok(Message::Reply(r)) = parse_message(&line) {
                let _ = parse_integer(&r);
            }
        }
    }
}
