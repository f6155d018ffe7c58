//! `sensor_msgs/msg/JointState` as ROS 2 writes it: CDR (XCDR1), a 4-byte
//! encapsulation header saying the byte order, then the fields, each
//! aligned to its size from the end of the header —
//!
//! ```text
//! std_msgs/Header header     (builtin_interfaces/Time stamp: int32 sec, uint32 nanosec;
//!                             string frame_id)
//! string[] name
//! float64[] position
//! float64[] velocity
//! float64[] effort
//! ```
//!
//! Decoded with every length checked against the bytes left before
//! anything is allocated: a recording is input from outside.

/// The schema name of the messages this decodes.
pub const SCHEMA_NAME: &str = "sensor_msgs/msg/JointState";

/// One message: the joints' names and, per joint, what was measured.
#[derive(Clone, Debug, PartialEq)]
pub struct JointState {
    /// The header's stamp, in nanoseconds since its clock's epoch.
    pub stamp_ns: i64,
    pub name: Vec<String>,
    pub position: Vec<f64>,
    pub velocity: Vec<f64>,
    pub effort: Vec<f64>,
}

/// Decodes one message's bytes; an error says what does not fit.
pub fn decode(data: &[u8]) -> Result<JointState, String> {
    let Some((header, body)) = data.split_first_chunk::<4>() else {
        return Err(format!(
            "{} bytes, shorter than a CDR encapsulation header",
            data.len()
        ));
    };
    let little = match header[1] {
        0x00 => false,
        0x01 => true,
        0x02 | 0x03 => {
            return Err("parameter-list CDR (PL_CDR), not the plain CDR ROS 2 writes".into());
        }
        kind => return Err(format!("unknown CDR encapsulation kind {kind:#04x}")),
    };
    let mut r = Reader {
        body,
        at: 0,
        little,
    };
    let sec = r.u32()? as i32;
    let nanosec = r.u32()?;
    if nanosec >= 1_000_000_000 {
        return Err(format!(
            "stamp nanoseconds {nanosec} are not below one second"
        ));
    }
    r.string()?; // frame_id
    let count = r.u32()? as usize;
    // Each name takes at least its length and its terminating NUL.
    if count > r.left() / 5 {
        return Err(format!(
            "{count} joint names do not fit in {} bytes",
            r.left()
        ));
    }
    let name = (0..count)
        .map(|_| r.string())
        .collect::<Result<Vec<_>, _>>()?;
    let position = r.doubles("position")?;
    let velocity = r.doubles("velocity")?;
    let effort = r.doubles("effort")?;
    // A writer may pad the message to a multiple of its alignment.
    if r.left() > 7 {
        return Err(format!("{} bytes after the effort", r.left()));
    }
    Ok(JointState {
        stamp_ns: i64::from(sec) * 1_000_000_000 + i64::from(nanosec),
        name,
        position,
        velocity,
        effort,
    })
}

/// A message's body, read field by field.
struct Reader<'a> {
    body: &'a [u8],
    at: usize,
    little: bool,
}

impl Reader<'_> {
    fn left(&self) -> usize {
        self.body.len() - self.at
    }

    /// `n` bytes, after padding to a multiple of `align` from the body's
    /// start.
    fn take(&mut self, n: usize, align: usize) -> Result<&[u8], String> {
        let start = self.at.next_multiple_of(align);
        let end = start
            .checked_add(n)
            .filter(|&end| end <= self.body.len())
            .ok_or_else(|| {
                format!(
                    "ends early: {n} bytes wanted at byte {}, {} there",
                    start + 4,
                    self.body.len().saturating_sub(start)
                )
            })?;
        self.at = end;
        Ok(&self.body[start..end])
    }

    fn u32(&mut self) -> Result<u32, String> {
        let bytes: [u8; 4] = self.take(4, 4)?.try_into().expect("four bytes");
        Ok(match self.little {
            true => u32::from_le_bytes(bytes),
            false => u32::from_be_bytes(bytes),
        })
    }

    fn f64(&mut self) -> Result<f64, String> {
        let bytes: [u8; 8] = self.take(8, 8)?.try_into().expect("eight bytes");
        Ok(match self.little {
            true => f64::from_le_bytes(bytes),
            false => f64::from_be_bytes(bytes),
        })
    }

    /// A string: its length with the terminating NUL, then its bytes.
    fn string(&mut self) -> Result<String, String> {
        let n = self.u32()? as usize;
        if n == 0 || n > self.left() {
            return Err(format!(
                "a string of {n} bytes where {} are left (at least its NUL)",
                self.left()
            ));
        }
        let bytes = self.take(n, 1)?;
        let (nul, text) = bytes.split_last().expect("at least one byte");
        if *nul != 0 {
            return Err("a string without its terminating NUL".into());
        }
        String::from_utf8(text.to_vec()).map_err(|_| "a string that is not UTF-8".into())
    }

    /// A sequence of float64, `field` named in errors.
    fn doubles(&mut self, field: &str) -> Result<Vec<f64>, String> {
        let n = self.u32()? as usize;
        if n > self.left() / 8 {
            return Err(format!(
                "{field}: {n} values do not fit in {} bytes",
                self.left()
            ));
        }
        (0..n).map(|_| self.f64()).collect()
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use serde::Serialize;

    use super::*;

    #[derive(Serialize)]
    pub(crate) struct Time {
        pub sec: i32,
        pub nanosec: u32,
    }

    #[derive(Serialize)]
    pub(crate) struct Header {
        pub stamp: Time,
        pub frame_id: String,
    }

    /// The message as the `cdr` crate (serde) encodes it: the reference
    /// the decoder is checked against, and what the stage's tests record.
    #[derive(Serialize)]
    pub(crate) struct Message {
        pub header: Header,
        pub name: Vec<String>,
        pub position: Vec<f64>,
        pub velocity: Vec<f64>,
        pub effort: Vec<f64>,
    }

    fn message() -> Message {
        Message {
            header: Header {
                stamp: Time {
                    sec: 1_700_000_012,
                    nanosec: 340_000_001,
                },
                frame_id: "base".into(),
            },
            name: vec!["shoulder_pan_joint".into(), "elbow".into(), "w".into()],
            position: vec![0.5, -1.25, 3.0],
            velocity: vec![0.0, 1e-3, -2.0],
            effort: vec![10.0, -0.5, 0.25],
        }
    }

    fn expected() -> JointState {
        let m = message();
        JointState {
            stamp_ns: 1_700_000_012_340_000_001,
            name: m.name,
            position: m.position,
            velocity: m.velocity,
            effort: m.effort,
        }
    }

    #[test]
    fn decodes_what_the_cdr_crate_encodes_in_either_byte_order() {
        let le = cdr::serialize::<_, _, cdr::CdrLe>(&message(), cdr::Infinite).unwrap();
        let be = cdr::serialize::<_, _, cdr::CdrBe>(&message(), cdr::Infinite).unwrap();
        assert_eq!(decode(&le), Ok(expected()));
        assert_eq!(decode(&be), Ok(expected()));
        // Alignment counts from the header's end: the frame id's length
        // shifts where the doubles start.
        let mut m = message();
        m.header.frame_id = "ab".into();
        let bytes = cdr::serialize::<_, _, cdr::CdrLe>(&m, cdr::Infinite).unwrap();
        assert_eq!(decode(&bytes).unwrap().position, expected().position);
    }

    #[test]
    fn lengths_that_do_not_fit_are_refused_before_allocating() {
        let bytes = cdr::serialize::<_, _, cdr::CdrLe>(&message(), cdr::Infinite).unwrap();
        // The frame id's length claims nearly 4 GiB.
        let mut long = bytes.clone();
        long[12..16].copy_from_slice(&0xFFFF_FFF0u32.to_le_bytes());
        assert!(
            decode(&long)
                .unwrap_err()
                .contains("string of 4294967280 bytes")
        );
        // The name count claims a billion names.
        let mut many = bytes.clone();
        many[24..28].copy_from_slice(&1_000_000_000u32.to_le_bytes());
        assert!(
            decode(&many)
                .unwrap_err()
                .contains("1000000000 joint names do not fit")
        );
        for cut in [0, 3, 10, bytes.len() - 1] {
            assert!(decode(&bytes[..cut]).is_err(), "cut at {cut}");
        }
        let mut parameter_list = bytes.clone();
        parameter_list[1] = 0x03;
        assert!(decode(&parameter_list).unwrap_err().contains("PL_CDR"));
        let mut trailing = bytes;
        trailing.extend_from_slice(&[0; 8]);
        assert!(
            decode(&trailing)
                .unwrap_err()
                .contains("8 bytes after the effort")
        );
    }
}
