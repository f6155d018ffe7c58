//! Reading an MCAP file front to back once, trusting nothing unchecked:
//! what the trajectory log's reader and a recording's reader share. The
//! data section's, the summary section's and every chunk's CRC-32 are
//! verified (where the writer stored them), every chunk before any of its
//! messages is used, no record or decompressed chunk may be larger than
//! [`RECORD_LIMIT`], and every length prefix of a record a reader uses is
//! checked against the record first, so a damaged length cannot make the
//! reader allocate without bound.

use std::path::Path;

use mcap::records::{Record, op};
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};

use crate::{Error, Result};

/// The largest record, or decompressed chunk, a file may hold (1 GiB):
/// alnlab's writer makes chunks of under 1 MiB, so only a damaged length
/// field comes near it.
pub const RECORD_LIMIT: usize = 1 << 30;

/// The records a reader asks for, beside the data end and footer every
/// read needs.
#[derive(Clone, Copy, Debug)]
pub struct Wanted {
    pub schemas: bool,
    pub channels: bool,
    pub messages: bool,
    pub metadata: bool,
}

/// Reads the MCAP file `path` held in `bytes`, handing each wanted record
/// of its data section to `record` in file order (the summary section
/// repeats schemas, channels and metadata: its records are not handed
/// on). An error of `record` ends the read. A file that starts as MCAP
/// does and then fails is damaged (exit 1); one that does not is another
/// kind of file (exit 2); one that ends before its footer is unfinished or
/// truncated.
pub fn read(
    path: &Path,
    bytes: &[u8],
    wanted: Wanted,
    mut record: impl FnMut(Record<'_>) -> Result<()>,
) -> Result<()> {
    let bad = |what: String| Error::bad_file(path, what);
    let corrupt = |e: mcap::McapError| {
        if bytes.starts_with(mcap::MAGIC) {
            Error::damaged(path, format!("not an intact MCAP file ({e})"))
        } else {
            bad(format!("not an MCAP file ({e})"))
        }
    };
    // Fuzzing explores the parser behind the CRCs.
    let check = !cfg!(fuzzing);
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_validate_data_section_crc(check)
            .with_validate_summary_section_crc(check)
            .with_prevalidate_chunk_crcs(check)
            .with_record_length_limit(RECORD_LIMIT),
    );
    let used = |opcode: u8| match opcode {
        op::SCHEMA => wanted.schemas,
        op::CHANNEL => wanted.channels,
        op::MESSAGE => wanted.messages,
        op::METADATA => wanted.metadata,
        op::DATA_END | op::FOOTER => true,
        // Header, indexes, statistics: passed over unparsed.
        _ => false,
    };
    let mut unread = bytes;
    let mut data_ended = false;
    let mut footer_seen = false;
    while let Some(event) = reader.next_event() {
        let (opcode, data) = match event.map_err(corrupt)? {
            LinearReadEvent::ReadRequest(need) => {
                let n = need.min(unread.len());
                reader.insert(n).copy_from_slice(&unread[..n]);
                reader.notify_read(n);
                unread = &unread[n..];
                continue;
            }
            LinearReadEvent::Record { opcode, data } => (opcode, data),
        };
        if !used(opcode) {
            continue;
        }
        if !fields_fit(opcode, data) {
            return Err(bad(format!(
                "record with opcode {opcode:#04x} has a field longer than the record"
            )));
        }
        match mcap::parse_record(opcode, data).map_err(corrupt)? {
            Record::Footer(_) => footer_seen = true,
            _ if data_ended => {}
            Record::DataEnd(_) => data_ended = true,
            parsed => record(parsed)?,
        }
    }
    if !data_ended || !footer_seen {
        return Err(bad(
            "MCAP file ends before its footer (unfinished or truncated)".into(),
        ));
    }
    Ok(())
}

/// Whether every length prefix in a record stays within the record. mcap's
/// parser reserves the length a string declares before reading it, so an
/// unchecked damaged prefix could ask for 4 GiB.
fn fields_fit(opcode: u8, data: &[u8]) -> bool {
    let mut fields = Fields(data);
    match opcode {
        // id, name, encoding, data
        op::SCHEMA => fields.skip(2) && fields.string() && fields.string() && fields.string(),
        // id, schema id, topic, message encoding, metadata
        op::CHANNEL => fields.skip(4) && fields.string() && fields.string() && fields.map(),
        // name, metadata
        op::METADATA => fields.string() && fields.map(),
        // fixed-size fields, then the rest of the record
        _ => true,
    }
}

/// The unread rest of a record, consumed field by field.
struct Fields<'a>(&'a [u8]);

impl Fields<'_> {
    fn skip(&mut self, n: usize) -> bool {
        match self.0.get(n..) {
            Some(rest) => {
                self.0 = rest;
                true
            }
            None => false,
        }
    }

    /// A `u32` length prefix, then that many bytes.
    fn string(&mut self) -> bool {
        let Some(prefix) = self.0.first_chunk::<4>() else {
            return false;
        };
        let n = u32::from_le_bytes(*prefix) as usize;
        self.skip(4) && self.skip(n)
    }

    /// A `u32` byte length, then string pairs filling exactly that many bytes.
    fn map(&mut self) -> bool {
        let Some(prefix) = self.0.first_chunk::<4>() else {
            return false;
        };
        let n = u32::from_le_bytes(*prefix) as usize;
        let Some(entries) = self.0.get(4..).and_then(|rest| rest.get(..n)) else {
            return false;
        };
        let mut entries = Fields(entries);
        while !entries.0.is_empty() {
            if !(entries.string() && entries.string()) {
                return false;
            }
        }
        self.skip(4 + n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn length_prefixes_must_stay_within_their_record() {
        let string = |s: &str| [&(s.len() as u32).to_le_bytes()[..], s.as_bytes()].concat();
        let pair = [string("k"), string("v")].concat();
        let map = [&(pair.len() as u32).to_le_bytes()[..], &pair].concat();
        let channel = [&[1, 0, 1, 0][..], &string("/t"), &string("cdr"), &map].concat();
        assert!(fields_fit(op::CHANNEL, &channel));
        assert!(fields_fit(
            op::METADATA,
            &[string("m"), map.clone()].concat()
        ));
        // The topic claims nearly 4 GiB.
        let mut long = channel.clone();
        long[4..8].copy_from_slice(&0xFFFF_FFF0u32.to_le_bytes());
        assert!(!fields_fit(op::CHANNEL, &long));
        // The map claims one byte more than it holds.
        let mut over = channel.clone();
        let at = channel.len() - map.len();
        over[at] += 1;
        assert!(!fields_fit(op::CHANNEL, &over));
        assert!(!fields_fit(op::CHANNEL, &channel[..channel.len() - 1]));
        // A schema: id, name, encoding, then its text.
        let schema = [
            &[1, 0][..],
            &string("a/msg/B"),
            &string("ros2msg"),
            &string("int32 x"),
        ]
        .concat();
        assert!(fields_fit(op::SCHEMA, &schema));
        assert!(!fields_fit(op::SCHEMA, &schema[..schema.len() - 1]));
    }
}
