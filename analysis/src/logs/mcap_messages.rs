//! The messages of an MCAP file, in file order, read with the `mcap` crate's
//! own sans-io reader, with every length inside a schema or channel record
//! checked against the record's size before the crate parses it.
//!
//! Why not `mcap::MessageStream`: the crate (0.26, the newest) reads a
//! string's 32-bit length and allocates that many bytes before reading them,
//! so one flipped byte in a 2 KB bag asked for 4 GiB, and the process
//! aborted where memory is capped or not overcommitted (found by
//! scripts/hostile_campaign.py). Here a schema's or channel's strings, map
//! and data must fit in the record that holds them, and the records kinegen
//! does not use (metadata, attachments, the summary's indexes and
//! statistics) are never parsed. Chunks are decompressed by the crate, no
//! record may be longer than [`record_limit`], and the crate's calls stay
//! inside [`contained`] for the panics it still has.
use crate::logs::contained::contained;
use mcap::read::ChannelAccumulator;
use mcap::records::{op, Record};
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
use mcap::Channel;
use std::sync::Arc;

/// One message: its channel (topic, encodings, schema), receive time (ns)
/// and serialised bytes.
pub struct Message<'a> {
    pub channel: Arc<Channel<'static>>,
    pub log_time: u64,
    pub data: &'a [u8],
}

/// Why the messages stopped: after how many, and what was wrong.
#[derive(Debug, Clone, PartialEq)]
pub struct Corrupt {
    pub after: usize,
    pub why: String,
}

/// The longest record the reader buffers: 16 times the file, and at least
/// 64 MiB (a chunk decompresses to more than its bytes; a single camera
/// image may be larger than a short bag), so a forged length cannot make
/// it buffer more than that.
pub fn record_limit(file_bytes: usize) -> usize {
    file_bytes.saturating_mul(16).max(64 << 20)
}

/// Calls `each(message, bytes_read)` for every message of `buf` in file
/// order (`bytes_read` of `buf.len()`: how far the reader is, for progress).
pub fn for_each_message(
    buf: &[u8],
    mut each: impl FnMut(Message<'_>, usize),
) -> Result<usize, Corrupt> {
    let options = LinearReaderOptions::default().with_record_length_limit(record_limit(buf.len()));
    let mut reader = LinearReader::new_with_options(options);
    let mut channels = ChannelAccumulator::<'static>::default();
    let (mut fed, mut count) = (0usize, 0usize);
    loop {
        let corrupt = |why: String| Corrupt { after: count, why };
        let event = contained(|| reader.next_event())
            .map_err(|why| corrupt(format!("the MCAP reader failed ({why})")))?;
        let Some(event) = event else {
            return Ok(count);
        };
        match event.map_err(|e| corrupt(e.to_string()))? {
            LinearReadEvent::ReadRequest(need) => {
                let n = need.min(buf.len() - fed);
                reader.insert(n).copy_from_slice(&buf[fed..fed + n]);
                reader.notify_read(n);
                fed += n;
            }
            LinearReadEvent::Record { opcode, data } => {
                let Some(message) = record(opcode, data, &mut channels).map_err(corrupt)? else {
                    continue;
                };
                each(message, fed);
                count += 1;
            }
        }
    }
}

/// A record read: a message, or `None` for a schema or channel recorded in
/// `channels` and for every record kinegen does not use.
fn record<'a>(
    opcode: u8,
    data: &'a [u8],
    channels: &mut ChannelAccumulator<'static>,
) -> Result<Option<Message<'a>>, String> {
    match opcode {
        op::SCHEMA => check_schema(data)?,
        op::CHANNEL => check_channel(data)?,
        op::MESSAGE => {}
        _ => return Ok(None),
    }
    let parsed = contained(|| mcap::parse_record(opcode, data))
        .map_err(|why| format!("the MCAP reader failed ({why})"))?
        .map_err(|e| e.to_string())?;
    match parsed {
        Record::Schema { header, data } => channels.add_schema_from_slice(header, &data),
        Record::Channel(c) => channels.add_channel(c),
        Record::Message { header, data: _ } => {
            let channel = channels.get(header.channel_id).ok_or_else(|| {
                format!(
                    "a message of channel {} before that channel's record",
                    header.channel_id
                )
            })?;
            // the message's bytes are the record after its fixed header
            // (channel id, sequence, log and publish times: 22 bytes)
            return Ok(Some(Message {
                channel,
                log_time: header.log_time,
                data: &data[22..],
            }));
        }
        _ => Ok(()),
    }
    .map_err(|e| e.to_string())?;
    Ok(None)
}

/// A record's fields read in order, each length checked against what is
/// left of the record.
struct Fields<'a> {
    rest: &'a [u8],
    record: &'static str,
}

impl<'a> Fields<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], String> {
        if n > self.rest.len() {
            return Err(format!(
                "a {} record's {what} is {n} bytes long, but only {} bytes of the record are left",
                self.record,
                self.rest.len()
            ));
        }
        let (head, tail) = self.rest.split_at(n);
        self.rest = tail;
        Ok(head)
    }

    fn u32(&mut self, what: &str) -> Result<usize, String> {
        let b = self.take(4, what)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
    }

    /// A length-prefixed string or byte array.
    fn sized(&mut self, what: &str) -> Result<&'a [u8], String> {
        let n = self.u32(what)?;
        self.take(n, what)
    }
}

/// Schema: id (u16), name, encoding, data.
fn check_schema(data: &[u8]) -> Result<(), String> {
    let mut f = Fields {
        rest: data,
        record: "schema",
    };
    f.take(2, "id")?;
    f.sized("name")?;
    f.sized("encoding")?;
    f.sized("data")?;
    Ok(())
}

/// Channel: id and schema id (u16 each), topic, message encoding, and the
/// metadata map (its length in bytes, then key and value strings).
fn check_channel(data: &[u8]) -> Result<(), String> {
    let mut f = Fields {
        rest: data,
        record: "channel",
    };
    f.take(4, "ids")?;
    f.sized("topic")?;
    f.sized("message encoding")?;
    let mut map = Fields {
        rest: f.sized("metadata")?,
        record: "channel",
    };
    while !map.rest.is_empty() {
        map.sized("metadata key")?;
        map.sized("metadata value")?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A channel record: ids, topic, encoding, then a metadata map holding
    /// `key` with `value`, each string's length as given.
    fn channel(topic_len: u32, key_len: u32) -> Vec<u8> {
        let mut r = vec![1, 0, 0, 0];
        r.extend(topic_len.to_le_bytes());
        r.extend(b"/js");
        r.extend(3u32.to_le_bytes());
        r.extend(b"cdr");
        let mut map = key_len.to_le_bytes().to_vec();
        map.extend(b"key");
        map.extend(5u32.to_le_bytes());
        map.extend(b"value");
        r.extend((map.len() as u32).to_le_bytes());
        r.extend(map);
        r
    }

    #[test]
    fn a_channel_whose_strings_fit_passes_and_a_forged_length_is_refused() {
        assert_eq!(check_channel(&channel(3, 3)), Ok(()));
        let e = check_channel(&channel(0xff00_0000, 3)).unwrap_err();
        assert!(e.contains("topic is 4278190080 bytes long"), "{e}");
        let e = check_channel(&channel(3, 40)).unwrap_err();
        assert!(e.contains("metadata key"), "{e}");
    }

    #[test]
    fn a_schema_whose_data_overruns_its_record_is_refused() {
        let mut r = vec![1, 0];
        for s in [&b"std_msgs/Header"[..], b"ros2msg"] {
            r.extend((s.len() as u32).to_le_bytes());
            r.extend(s);
        }
        r.extend(100u32.to_le_bytes());
        r.extend(b"uint32 x");
        let e = check_schema(&r).unwrap_err();
        assert!(e.contains("schema record's data is 100 bytes"), "{e}");
    }
}
