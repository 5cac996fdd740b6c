//! Thorlabs APT binary messages, as pure functions (Thorlabs "APT Communications Protocol",
//! issue 37+: section 2 "Message structure", section 3 motor control messages). Every message
//! starts with a 6-byte little-endian header: message id (u16), then either two parameter bytes
//! or the length (u16) of the data that follows, the destination (| 0x80 when data follows) and
//! the source.

use ffdic_hw::{HwError, HwResult};

/// The PC's address.
pub const HOST: u8 = 0x01;
/// A single-channel USB controller (KDC101, TDC001, KST101…).
pub const GENERIC_USB: u8 = 0x50;
const DATA_FOLLOWS: u8 = 0x80;
pub const HEADER_BYTES: usize = 6;
/// No message the driver reads is longer (HW_GET_INFO, the longest common one, is 84 bytes); a
/// header that announces more is noise.
pub const MAX_DATA_BYTES: usize = 128;

/// Message ids used here (protocol manual, section 3).
pub mod id {
    pub const HW_RESPONSE: u16 = 0x0080;
    pub const HW_RICHRESPONSE: u16 = 0x0081;
    pub const REQ_POSCOUNTER: u16 = 0x0411;
    pub const GET_POSCOUNTER: u16 = 0x0412;
    pub const HOME: u16 = 0x0443;
    pub const HOMED: u16 = 0x0444;
    pub const MOVE_ABSOLUTE: u16 = 0x0453;
    pub const MOVE_COMPLETED: u16 = 0x0464;
    pub const MOVE_STOP: u16 = 0x0465;
    pub const MOVE_STOPPED: u16 = 0x0466;
    /// Stepper controllers' status update (request 0x0480, unprompted or requested 0x0481).
    pub const REQ_STATUSUPDATE: u16 = 0x0480;
    pub const GET_STATUSUPDATE: u16 = 0x0481;
    /// DC servo controllers' status update (request 0x0490, unprompted or requested 0x0491).
    pub const REQ_DCSTATUSUPDATE: u16 = 0x0490;
    pub const GET_DCSTATUSUPDATE: u16 = 0x0491;
}

/// Status bits of the status update structures (manual, MGMSG_MOT_GET_STATUSUPDATE).
pub mod status {
    pub const CW_HARD_LIMIT: u32 = 0x0000_0001;
    pub const CCW_HARD_LIMIT: u32 = 0x0000_0002;
    pub const IN_MOTION_CW: u32 = 0x0000_0010;
    pub const IN_MOTION_CCW: u32 = 0x0000_0020;
    pub const JOGGING_CW: u32 = 0x0000_0040;
    pub const JOGGING_CCW: u32 = 0x0000_0080;
    pub const HOMING: u32 = 0x0000_0200;
    pub const HOMED: u32 = 0x0000_0400;
    pub const MOVING: u32 = IN_MOTION_CW | IN_MOTION_CCW | JOGGING_CW | JOGGING_CCW | HOMING;
    pub const HARD_LIMIT: u32 = CW_HARD_LIMIT | CCW_HARD_LIMIT;
}

#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Payload {
    Params(u8, u8),
    Data(Vec<u8>),
}

#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Frame {
    pub id: u16,
    /// Destination without the data flag.
    pub dest: u8,
    pub source: u8,
    pub payload: Payload,
}

impl Frame {
    pub fn short(id: u16, p1: u8, p2: u8, dest: u8, source: u8) -> Self {
        Self {
            id,
            dest,
            source,
            payload: Payload::Params(p1, p2),
        }
    }

    pub fn long(id: u16, data: Vec<u8>, dest: u8, source: u8) -> Self {
        Self {
            id,
            dest,
            source,
            payload: Payload::Data(data),
        }
    }

    pub fn encode(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(HEADER_BYTES);
        out.extend_from_slice(&self.id.to_le_bytes());
        match &self.payload {
            Payload::Params(p1, p2) => {
                out.extend_from_slice(&[*p1, *p2, self.dest, self.source]);
            }
            Payload::Data(data) => {
                out.extend_from_slice(&(data.len() as u16).to_le_bytes());
                out.extend_from_slice(&[self.dest | DATA_FOLLOWS, self.source]);
                out.extend_from_slice(data);
            }
        }
        out
    }

    pub fn data(&self) -> &[u8] {
        match &self.payload {
            Payload::Data(d) => d,
            Payload::Params(..) => &[],
        }
    }
}

/// Addresses an APT message may carry: host, rack, bays 1–10, generic USB unit.
fn is_address(a: u8) -> bool {
    matches!(a, HOST | 0x11 | 0x21..=0x2A | GENERIC_USB)
}

/// Decodes the frame at the start of `bytes`: `Ok(None)` while it is incomplete, the frame and
/// the bytes it used otherwise. A header whose addresses or length cannot be APT is an error at
/// once, so noise is reported rather than waited on.
pub fn decode(bytes: &[u8]) -> HwResult<Option<(Frame, usize)>> {
    if bytes.len() < HEADER_BYTES {
        return Ok(None);
    }
    let id = u16::from_le_bytes([bytes[0], bytes[1]]);
    let dest = bytes[4] & !DATA_FOLLOWS;
    let source = bytes[5];
    if !is_address(dest) || !is_address(source) || dest == source {
        return Err(HwError::Protocol(format!(
            "APT header {:02x?} has no valid destination/source",
            &bytes[..HEADER_BYTES]
        )));
    }
    if bytes[4] & DATA_FOLLOWS == 0 {
        let frame = Frame::short(id, bytes[2], bytes[3], dest, source);
        return Ok(Some((frame, HEADER_BYTES)));
    }
    let len = u16::from_le_bytes([bytes[2], bytes[3]]) as usize;
    if len > MAX_DATA_BYTES {
        return Err(HwError::Protocol(format!(
            "APT message 0x{id:04x} announces {len} data bytes (at most {MAX_DATA_BYTES})"
        )));
    }
    if bytes.len() < HEADER_BYTES + len {
        return Ok(None);
    }
    let data = bytes[HEADER_BYTES..HEADER_BYTES + len].to_vec();
    Ok(Some((
        Frame::long(id, data, dest, source),
        HEADER_BYTES + len,
    )))
}

/// MOVE_ABSOLUTE with data: channel (u16), absolute position in counts (i32).
pub fn move_absolute(dest: u8, channel: u16, counts: i32) -> Frame {
    let mut data = channel.to_le_bytes().to_vec();
    data.extend_from_slice(&counts.to_le_bytes());
    Frame::long(id::MOVE_ABSOLUTE, data, dest, HOST)
}

/// A header-only request about one channel (HOME, REQ_POSCOUNTER, REQ_DCSTATUSUPDATE…).
pub fn request(message: u16, dest: u8, channel: u16) -> Frame {
    Frame::short(message, channel as u8, 0, dest, HOST)
}

/// MOVE_STOP; `profiled` decelerates, otherwise the motor stops at once.
pub fn move_stop(dest: u8, channel: u16, profiled: bool) -> Frame {
    Frame::short(
        id::MOVE_STOP,
        channel as u8,
        if profiled { 2 } else { 1 },
        dest,
        HOST,
    )
}

/// The status structure carried by GET_STATUSUPDATE, GET_DCSTATUSUPDATE, MOVE_COMPLETED and
/// MOVE_STOPPED: channel, position, 4 bytes that differ by controller family, status bits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MotorStatus {
    pub channel: u16,
    pub position_counts: i32,
    pub bits: u32,
}

pub fn parse_status(frame: &Frame) -> HwResult<MotorStatus> {
    let d = frame.data();
    if d.len() < 14 {
        return Err(HwError::Protocol(format!(
            "APT message 0x{:04x} carries {} bytes, a status needs 14",
            frame.id,
            d.len()
        )));
    }
    Ok(MotorStatus {
        channel: u16::from_le_bytes([d[0], d[1]]),
        position_counts: i32::from_le_bytes([d[2], d[3], d[4], d[5]]),
        bits: u32::from_le_bytes([d[10], d[11], d[12], d[13]]),
    })
}

/// The 14-byte status structure (DC servo layout: velocity and a reserved word in the middle).
pub fn status_data(s: MotorStatus) -> Vec<u8> {
    let mut d = s.channel.to_le_bytes().to_vec();
    d.extend_from_slice(&s.position_counts.to_le_bytes());
    d.extend_from_slice(&[0; 4]);
    d.extend_from_slice(&s.bits.to_le_bytes());
    d
}

/// GET_POSCOUNTER: channel and position in counts.
pub fn parse_poscounter(frame: &Frame) -> HwResult<(u16, i32)> {
    match frame.data() {
        [c0, c1, p0, p1, p2, p3, ..] => Ok((
            u16::from_le_bytes([*c0, *c1]),
            i32::from_le_bytes([*p0, *p1, *p2, *p3]),
        )),
        d => Err(HwError::Protocol(format!(
            "GET_POSCOUNTER carries {} bytes, needs 6",
            d.len()
        ))),
    }
}

/// HW_RICHRESPONSE (error report): the message it concerns, a code and a text (64 bytes, NUL
/// padded).
pub fn describe_rich_response(frame: &Frame) -> String {
    let d = frame.data();
    if d.len() < 4 {
        return "error report without details".into();
    }
    let about = u16::from_le_bytes([d[0], d[1]]);
    let code = u16::from_le_bytes([d[2], d[3]]);
    let text: String = String::from_utf8_lossy(&d[4..])
        .trim_end_matches('\0')
        .trim()
        .to_string();
    format!("controller error {code} about message 0x{about:04x}: {text}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn move_absolute_encodes_header_then_data() {
        // Worked by hand from the header layout: id 0x0453 little endian, 6 data bytes, bay 2
        // (0x22) | 0x80, from the host; then channel 1 and 65536 counts.
        let f = move_absolute(0x22, 1, 0x0001_0000);
        assert_eq!(
            f.encode(),
            [0x53, 0x04, 0x06, 0x00, 0xA2, 0x01, 0x01, 0x00, 0x00, 0x00, 0x01, 0x00]
        );
        let (back, used) = decode(&f.encode()).unwrap().unwrap();
        assert_eq!((back, used), (f, 12));
    }

    #[test]
    fn short_frames_and_incomplete_input() {
        let home = request(id::HOME, GENERIC_USB, 1).encode();
        assert_eq!(home, [0x43, 0x04, 0x01, 0x00, 0x50, 0x01]);
        assert_eq!(decode(&home[..5]).unwrap(), None);
        let mut reply = Frame::long(
            id::GET_POSCOUNTER,
            vec![1, 0, 0xFF, 0xFF, 0xFF, 0xFF],
            HOST,
            GENERIC_USB,
        )
        .encode();
        assert_eq!(decode(&reply[..9]).unwrap(), None);
        reply.extend_from_slice(&home); // A second frame behind the first is left alone.
        let (frame, used) = decode(&reply).unwrap().unwrap();
        assert_eq!(used, 12);
        assert_eq!(parse_poscounter(&frame).unwrap(), (1, -1));
    }

    #[test]
    fn status_round_trip() {
        let s = MotorStatus {
            channel: 1,
            position_counts: -123_456,
            bits: status::HOMED | status::IN_MOTION_CW,
        };
        let f = Frame::long(id::GET_DCSTATUSUPDATE, status_data(s), HOST, GENERIC_USB);
        let (back, _) = decode(&f.encode()).unwrap().unwrap();
        assert_eq!(parse_status(&back).unwrap(), s);
        let short = Frame::long(id::MOVE_COMPLETED, vec![1, 0], HOST, GENERIC_USB);
        assert!(matches!(parse_status(&short), Err(HwError::Protocol(_))));
    }

    #[test]
    fn noise_is_refused_without_waiting_for_more() {
        for noise in [
            [0xFF, 0xFE, 0xFD, 0x80, 0xAA, 0x55],
            [0x12, 0x04, 0x06, 0x00, 0x81, 0x81],
            [0x12, 0x04, 0xFF, 0x00, 0x81, 0x50],
        ] {
            assert!(
                matches!(decode(&noise), Err(HwError::Protocol(_))),
                "{noise:02x?}"
            );
        }
    }

    #[test]
    fn random_bytes_never_panic() {
        // A small linear congruential generator: deterministic noise without a dependency.
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        let mut next = || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1);
            (state >> 33) as u8
        };
        for len in 0..400 {
            let bytes: Vec<u8> = (0..len % 40).map(|_| next()).collect();
            if let Ok(Some((frame, used))) = decode(&bytes) {
                assert!(used <= bytes.len());
                let _ = parse_status(&frame);
                let _ = parse_poscounter(&frame);
                let _ = describe_rich_response(&frame);
            }
        }
    }
}
