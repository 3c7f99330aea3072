//! A bag whose record lengths lie (issue 67): the MCAP reader refuses a
//! string longer than its record before the `mcap` crate parses it (the
//! crate allocates a string's written length first: one flipped byte asked
//! for 4 GiB and aborted the process), and it reads every message of an
//! honest bag, chunked or not, as the crate's own `MessageStream` does.
use kinegen_analysis::logs::mcap_messages::for_each_message;
use mcap::records::MessageHeader;
use mcap::{WriteOptions, Writer};
use std::collections::BTreeMap;
use std::io::Cursor;

const TOPIC: &str = "/joint_states_of_a_long_name";

/// A small bag: one schema, one channel with metadata, three messages.
fn bag(chunked: bool) -> Vec<u8> {
    let mut out = Cursor::new(Vec::new());
    {
        let mut w: Writer<_> = WriteOptions::new()
            .use_chunks(chunked)
            .compression(None)
            .create(&mut out)
            .unwrap();
        let schema = w
            .add_schema("std_msgs/msg/UInt32", "ros2msg", b"uint32 data")
            .unwrap();
        let meta = BTreeMap::from([("offered_qos_profiles".to_string(), "x".to_string())]);
        let ch = w.add_channel(schema, TOPIC, "cdr", &meta).unwrap();
        for k in 0..3u32 {
            let header = MessageHeader {
                channel_id: ch,
                sequence: k,
                log_time: 1_000 + u64::from(k),
                publish_time: 1_000 + u64::from(k),
            };
            w.write_to_known_channel(&header, &[0, 1, 0, 0, k as u8, 0, 0, 0])
                .unwrap();
        }
        w.finish().unwrap();
    }
    out.into_inner()
}

fn messages(buf: &[u8]) -> Result<Vec<(String, u64, Vec<u8>)>, String> {
    let mut got = Vec::new();
    for_each_message(buf, |m, _| {
        got.push((m.channel.topic.clone(), m.log_time, m.data.to_vec()))
    })
    .map_err(|c| c.why)?;
    Ok(got)
}

#[test]
fn every_message_of_an_honest_bag_is_read_as_the_crate_reads_it() {
    for chunked in [false, true] {
        let buf = bag(chunked);
        let ours = messages(&buf).unwrap();
        let theirs: Vec<_> = mcap::MessageStream::new(&buf)
            .unwrap()
            .map(|m| {
                let m = m.unwrap();
                (m.channel.topic.clone(), m.log_time, m.data.to_vec())
            })
            .collect();
        assert_eq!(ours.len(), 3);
        assert_eq!(ours, theirs, "chunked: {chunked}");
    }
}

#[test]
fn a_string_longer_than_its_record_is_refused_before_it_is_allocated() {
    for chunked in [false, true] {
        let mut buf = bag(chunked);
        // the channel's topic length (u32, little-endian) sits just before
        // the topic's bytes; the first occurrence is the data section's
        let at = buf
            .windows(TOPIC.len())
            .position(|w| w == TOPIC.as_bytes())
            .unwrap();
        buf[at - 4..at].copy_from_slice(&0xff00_0000u32.to_le_bytes());
        let e = messages(&buf).unwrap_err();
        assert!(
            e.contains("channel record's topic is 4278190080 bytes long"),
            "chunked: {chunked}: {e}"
        );
    }
}
