//! A message as ROS 2 serializes it (rmw's `cdr` encoding): the 4-byte encapsulation header of
//! plain little-endian CDR (`CDR_LE`, XCDR1), then the fields in declaration order, each aligned
//! to its size counted from the end of the header, strings as a `u32` length (the NUL included),
//! the bytes and a NUL, sequences as a `u32` count and the elements, fixed arrays as their
//! elements alone. The body is `cdr-encoding`'s (RustDDS's serde CDR).

use byteorder::LittleEndian;
use cdr_encoding::CdrSerializer;
use serde::Serialize;

/// The encapsulation header: representation identifier `CDR_LE` (0x0001), options 0.
pub const CDR_LE: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// Writes `message`, header first, into `out` (cleared first, its storage reused).
pub fn encode<T: Serialize>(message: &T, out: &mut Vec<u8>) -> Result<(), cdr_encoding::Error> {
    out.clear();
    out.extend_from_slice(&CDR_LE);
    // A serializer of its own counts alignment from 0: from the end of the header, as CDR does.
    message.serialize(&mut CdrSerializer::<_, LittleEndian>::new(&mut *out))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msg::{Header, Time};

    /// Against the bytes worked out by hand from the rules in the module documentation.
    #[test]
    fn a_header_encodes_as_cdr_lays_it_out() {
        let header = Header {
            stamp: Time {
                sec: 0x0102_0304,
                nanosec: 5,
            },
            frame_id: "odom".into(),
        };
        let mut out = Vec::new();
        encode(&header, &mut out).unwrap();
        let expected: Vec<u8> = [
            &CDR_LE[..],
            &[4, 3, 2, 1], // sec
            &[5, 0, 0, 0], // nanosec
            &[5, 0, 0, 0], // frame_id's length, the NUL included
            b"odom\0",     // frame_id
        ]
        .concat();
        assert_eq!(out, expected);
    }

    /// An `f64` after a string is aligned to 8 from the end of the encapsulation header.
    #[test]
    fn doubles_align_to_8_after_the_header() {
        #[derive(Serialize)]
        struct S {
            name: String,
            x: f64,
        }
        let mut out = Vec::new();
        encode(
            &S {
                name: "a".into(),
                x: 1.5,
            },
            &mut out,
        )
        .unwrap();
        // 4 (length) + 2 ("a\0") = 6, padded to 8, then the double.
        let mut expected = CDR_LE.to_vec();
        expected.extend([2, 0, 0, 0, b'a', 0, 0, 0]);
        expected.extend(1.5f64.to_le_bytes());
        assert_eq!(out, expected);
    }
}
