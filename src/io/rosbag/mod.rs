//! ROS 2 bags: a bag directory (`metadata.yaml` and its `.mcap` files) or one `.mcap` file, read
//! record by record (the chunks' CRCs checked) with the messages decoded from CDR ([`cdr`]) and
//! the sensors placed by the bag's tf ([`tf`]).
//!
//! A bag is read twice: once to list its topics and check every record, so a damaged file is
//! refused before anything is written, then for its messages.

pub mod cdr;
pub mod tf;

use super::IoError;
use mcap::records::Record;
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
use std::collections::{BTreeMap, HashMap};
use std::io::Read as _;
use std::path::{Path, PathBuf};

/// One topic of a bag.
#[derive(Debug, Clone, PartialEq)]
pub struct TopicInfo {
    /// The topic's name.
    pub name: String,
    /// Its message type (`sensor_msgs/msg/Image`).
    pub type_name: String,
    /// Its message encoding (`cdr` for ROS 2).
    pub encoding: String,
    /// Messages.
    pub count: usize,
    /// First and last log time, nanoseconds.
    pub first_ns: u64,
    /// Last log time.
    pub last_ns: u64,
    /// The longest time between two messages in a row, nanoseconds.
    pub largest_gap_ns: u64,
}

impl TopicInfo {
    /// Messages a second over the topic's span (0 for fewer than two).
    pub fn rate_hz(&self) -> f64 {
        let span = self.last_ns.saturating_sub(self.first_ns) as f64 * 1e-9;
        if self.count < 2 || span <= 0.0 {
            0.0
        } else {
            (self.count - 1) as f64 / span
        }
    }
}

/// A ROS 2 bag, its records checked and its topics listed.
#[derive(Debug, Clone)]
pub struct Bag {
    /// The path given.
    pub path: PathBuf,
    /// Its MCAP files, in order.
    pub files: Vec<PathBuf>,
    /// Its topics, by name.
    pub topics: Vec<TopicInfo>,
}

/// One message of a bag.
#[derive(Debug)]
pub struct Message<'a> {
    /// Its topic.
    pub topic: &'a TopicInfo,
    /// Its index among its topic's messages, from 0.
    pub index: usize,
    /// Its log time, nanoseconds.
    pub log_time_ns: u64,
    /// The serialized message.
    pub data: &'a [u8],
    /// The file it is in.
    pub file: &'a Path,
}

impl Message<'_> {
    /// An error about this message, naming the file, topic, message and time.
    pub fn error(&self, what: impl std::fmt::Display) -> IoError {
        message_error(
            self.file,
            &self.topic.name,
            self.index,
            self.log_time_ns,
            what,
        )
    }
}

/// An error about message `index` of `topic` in `file`, logged at `log_time_ns`.
pub fn message_error(
    file: &Path,
    topic: &str,
    index: usize,
    log_time_ns: u64,
    what: impl std::fmt::Display,
) -> IoError {
    IoError::content(
        file,
        format!(
            "topic {topic}, message {index} (log time {:.3} s): {what}",
            log_time_ns as f64 * 1e-9
        ),
    )
}

/// How to convert what stereotag cannot read into an MCAP bag.
const CONVERT: &str = "convert it to an MCAP ROS 2 bag: `pip install rosbags` then `rosbags-convert --src IN --dst OUT_DIR --dst-storage mcap`";

/// The MCAP files of a bag directory or file.
fn bag_files(path: &Path) -> Result<Vec<PathBuf>, IoError> {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
    if path.is_file() {
        return match ext {
            "mcap" => Ok(vec![path.to_owned()]),
            "bag" => Err(IoError::content(path, format!("a ROS 1 bag: {CONVERT}"))),
            "db3" => Err(IoError::content(
                path,
                format!("a ROS 2 bag stored as SQLite: {CONVERT}"),
            )),
            _ => Err(IoError::content(
                path,
                "not a ROS 2 bag: give a bag directory (metadata.yaml and .mcap files) or an .mcap file",
            )),
        };
    }
    let meta = path.join("metadata.yaml");
    let listed: Option<Vec<PathBuf>> = if meta.is_file() {
        let text = super::read_text(&meta)?;
        let yaml: serde_yaml_ng::Value = super::parse_yaml(&meta, &text)?;
        let info = &yaml["rosbag2_bagfile_information"];
        if info["storage_identifier"].as_str() == Some("sqlite3") {
            return Err(IoError::content(
                &meta,
                format!("the bag is stored as SQLite (storage_identifier: sqlite3): {CONVERT}"),
            ));
        }
        info["relative_file_paths"].as_sequence().map(|files| {
            files
                .iter()
                .filter_map(|f| f.as_str())
                .map(|f| path.join(f))
                .collect()
        })
    } else {
        None
    };
    let files = match listed {
        Some(files) => files,
        None => {
            let entries = std::fs::read_dir(path).map_err(|e| IoError::file(path, e))?;
            let mut files: Vec<PathBuf> = entries
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|e| e == "mcap"))
                .collect();
            files.sort();
            files
        }
    };
    if files.is_empty() {
        return Err(IoError::content(
            path,
            "no .mcap files: give a ROS 2 bag directory (metadata.yaml and .mcap files) or an .mcap file",
        ));
    }
    if let Some(missing) = files.iter().find(|f| !f.is_file()) {
        return Err(IoError::content(
            missing,
            "listed in the bag's metadata.yaml but missing",
        ));
    }
    Ok(files)
}

/// The records a bag is read for (schemas, channels, messages and chunks), parsed; `None` for the
/// others, which are passed over unparsed (mcap's parser panics on some damaged attachments).
fn parse(opcode: u8, body: &[u8]) -> Option<mcap::McapResult<Record<'_>>> {
    use mcap::records::op;
    matches!(opcode, op::SCHEMA | op::CHANNEL | op::MESSAGE | op::CHUNK)
        .then(|| mcap::parse_record(opcode, body))
}

/// Calls `on` with every record of an MCAP file, in file order (chunks unpacked by
/// [`chunk_records`]).
fn records(
    path: &Path,
    mut on: impl FnMut(Record<'_>) -> Result<(), IoError>,
) -> Result<(), IoError> {
    let mut file = std::fs::File::open(path).map_err(|e| IoError::file(path, e))?;
    let size = file.metadata().map_err(|e| IoError::file(path, e))?.len();
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_emit_chunks(true)
            .with_record_length_limit(usize::try_from(size).unwrap_or(usize::MAX))
            .with_validate_data_section_crc(true)
            .with_validate_summary_section_crc(true),
    );
    let damaged = |e: mcap::McapError| {
        let what = match e {
            mcap::McapError::UnexpectedEof => {
                "it ends in the middle of a record: the file is cut short".to_owned()
            }
            mcap::McapError::RecordTooLarge { len, .. } => format!(
                "a record of {len} bytes runs past its end ({size} bytes): the file is cut short or damaged"
            ),
            e => e.to_string(),
        };
        IoError::content(path, format!("not a whole MCAP file: {what}"))
    };
    while let Some(event) = reader.next_event() {
        match event.map_err(damaged)? {
            LinearReadEvent::ReadRequest(n) => {
                // At most a MiB at a time: a damaged length asks for more than the file holds.
                let read = file
                    .read(reader.insert(n.min(READ_SIZE)))
                    .map_err(|e| IoError::file(path, e))?;
                reader.notify_read(read);
            }
            LinearReadEvent::Record { data, opcode } => match parse(opcode, data) {
                None => {}
                Some(Ok(Record::Chunk { header, data })) => {
                    chunk_records(path, &header, &data, &mut on)?
                }
                Some(Ok(record)) => on(record)?,
                Some(Err(e)) => return Err(damaged(e)),
            },
        }
    }
    Ok(())
}

/// Calls `on` with every record of a chunk: decompressed (zstd, lz4) to the size its header
/// says, its CRC checked when it has one, each record's length checked against what is left.
fn chunk_records(
    path: &Path,
    header: &mcap::records::ChunkHeader,
    data: &[u8],
    on: &mut impl FnMut(Record<'_>) -> Result<(), IoError>,
) -> Result<(), IoError> {
    let bad = |what: String| {
        IoError::content(
            path,
            format!(
                "not a whole MCAP file: the chunk of messages from log time {:.3} s {what}",
                header.message_start_time as f64 * 1e-9
            ),
        )
    };
    let unpacked: std::borrow::Cow<'_, [u8]> = match header.compression.as_str() {
        "" => data.into(),
        "zstd" | "lz4" => {
            let mut out = Vec::new();
            let limit = header.uncompressed_size;
            let read = if header.compression == "zstd" {
                zstd::stream::read::Decoder::new(data)
                    .and_then(|d| d.take(limit).read_to_end(&mut out))
            } else {
                lz4::Decoder::new(data).and_then(|d| d.take(limit).read_to_end(&mut out))
            };
            read.map_err(|e| {
                bad(format!(
                    "cannot be decompressed ({}: {e})",
                    header.compression
                ))
            })?;
            out.into()
        }
        other => {
            return Err(bad(format!(
                "is compressed as `{other}` (zstd and lz4 are read)"
            )))
        }
    };
    if unpacked.len() as u64 != header.uncompressed_size {
        return Err(bad(format!(
            "holds {} bytes where its header says {}",
            unpacked.len(),
            header.uncompressed_size
        )));
    }
    if header.uncompressed_crc != 0 {
        let crc = crc32fast::hash(&unpacked);
        if crc != header.uncompressed_crc {
            return Err(bad(format!(
                "fails its CRC (expected {:08X}, got {crc:08X})",
                header.uncompressed_crc
            )));
        }
    }
    let mut rest: &[u8] = &unpacked;
    while !rest.is_empty() {
        let (op, len) = match rest {
            [op, l0, l1, l2, l3, l4, l5, l6, l7, ..] => (
                *op,
                u64::from_le_bytes([*l0, *l1, *l2, *l3, *l4, *l5, *l6, *l7]),
            ),
            _ => return Err(bad("ends inside a record's header".into())),
        };
        let body = &rest[9..];
        let Some(len) = usize::try_from(len).ok().filter(|&n| n <= body.len()) else {
            return Err(bad(format!(
                "has a record of {len} bytes where {} are left",
                body.len()
            )));
        };
        if let Some(record) = parse(op, &body[..len]) {
            on(record.map_err(|e| bad(format!("has a record that cannot be read: {e}")))?)?;
        }
        rest = &body[len..];
    }
    Ok(())
}

/// Bytes read from a bag file at a time.
const READ_SIZE: usize = 1 << 20;

/// A channel of one file: its topic's index in [`Bag::topics`].
type Channels = HashMap<u16, usize>;

impl Bag {
    /// Opens a bag directory or `.mcap` file: reads every record once, checking it, and lists the
    /// topics.
    pub fn open(path: &Path) -> Result<Bag, IoError> {
        let files = bag_files(path)?;
        let mut topics: BTreeMap<String, TopicInfo> = BTreeMap::new();
        for file in &files {
            let mut schemas: HashMap<u16, String> = HashMap::new();
            let mut channels: HashMap<u16, String> = HashMap::new();
            records(file, |record| {
                match record {
                    Record::Schema { header, .. } => {
                        schemas.insert(header.id, header.name);
                    }
                    Record::Channel(c) => {
                        let type_name = schemas.get(&c.schema_id).cloned().unwrap_or_default();
                        let topic = topics.entry(c.topic.clone()).or_insert(TopicInfo {
                            name: c.topic.clone(),
                            type_name: type_name.clone(),
                            encoding: c.message_encoding.clone(),
                            count: 0,
                            first_ns: 0,
                            last_ns: 0,
                            largest_gap_ns: 0,
                        });
                        if topic.type_name != type_name {
                            return Err(IoError::content(
                                file,
                                format!(
                                    "topic {} has two types, {} and {type_name}",
                                    c.topic, topic.type_name
                                ),
                            ));
                        }
                        channels.insert(c.id, c.topic);
                    }
                    Record::Message { header, .. } => {
                        let name = channels.get(&header.channel_id).ok_or_else(|| {
                            IoError::content(
                                file,
                                format!(
                                    "a message on channel {} before its channel record",
                                    header.channel_id
                                ),
                            )
                        })?;
                        let t = topics.get_mut(name).expect("listed with its channel");
                        if t.count == 0 {
                            t.first_ns = header.log_time;
                        } else {
                            let gap = header.log_time.saturating_sub(t.last_ns);
                            t.largest_gap_ns = t.largest_gap_ns.max(gap);
                        }
                        t.first_ns = t.first_ns.min(header.log_time);
                        t.last_ns = t.last_ns.max(header.log_time);
                        t.count += 1;
                    }
                    _ => {}
                }
                Ok(())
            })?;
        }
        Ok(Bag {
            path: path.to_owned(),
            files,
            topics: topics.into_values().collect(),
        })
    }

    /// The topic of this name.
    pub fn topic(&self, name: &str) -> Option<&TopicInfo> {
        self.topics.iter().find(|t| t.name == name)
    }

    /// The bag's topics and their types, one a line, for error messages.
    pub fn topic_list(&self) -> String {
        self.topics
            .iter()
            .map(|t| {
                let plural = if t.count == 1 { "" } else { "s" };
                format!(
                    "  {} ({}, {} message{plural})",
                    t.name, t.type_name, t.count
                )
            })
            .collect::<Vec<_>>()
            .join("\n")
    }

    /// Calls `on` with every message of the topics `wanted` says yes to, in file order.
    pub fn messages(
        &self,
        wanted: impl Fn(&TopicInfo) -> bool,
        mut on: impl FnMut(&Message<'_>) -> Result<(), IoError>,
    ) -> Result<(), IoError> {
        let mut seen = vec![0usize; self.topics.len()];
        for file in &self.files {
            let mut channels: Channels = HashMap::new();
            records(file, |record| {
                match record {
                    Record::Channel(c) => {
                        let i = self
                            .topics
                            .iter()
                            .position(|t| t.name == c.topic)
                            .expect("listed when opened");
                        channels.insert(c.id, i);
                    }
                    Record::Message { header, data } => {
                        let i = channels[&header.channel_id];
                        let topic = &self.topics[i];
                        let index = seen[i];
                        seen[i] += 1;
                        if wanted(topic) {
                            on(&Message {
                                topic,
                                index,
                                log_time_ns: header.log_time,
                                data: &data,
                                file,
                            })?;
                        }
                    }
                    _ => {}
                }
                Ok(())
            })?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write as _;

    /// Two message records (channel 1, sequence, log and publish time, then the data), as a
    /// chunk's records, and a record of an opcode the reader passes over (0x80).
    fn records_bytes() -> Vec<u8> {
        let mut out = Vec::new();
        for (k, data) in [&b"first"[..], b"second record"].into_iter().enumerate() {
            let mut body = Vec::new();
            body.extend(1u16.to_le_bytes());
            body.extend((k as u32).to_le_bytes());
            body.extend(100u64.to_le_bytes());
            body.extend(100u64.to_le_bytes());
            body.extend(data);
            out.push(mcap::records::op::MESSAGE);
            out.extend((body.len() as u64).to_le_bytes());
            out.extend(body);
        }
        out.push(0x80);
        out.extend(3u64.to_le_bytes());
        out.extend(b"app");
        out
    }

    fn header(compression: &str, raw: &[u8], crc: u32) -> mcap::records::ChunkHeader {
        mcap::records::ChunkHeader {
            message_start_time: 0,
            message_end_time: 0,
            uncompressed_size: raw.len() as u64,
            uncompressed_crc: crc,
            compression: compression.into(),
            compressed_size: 0,
        }
    }

    fn bodies(h: &mcap::records::ChunkHeader, data: &[u8]) -> Result<Vec<Vec<u8>>, IoError> {
        let mut got = Vec::new();
        chunk_records(Path::new("t.mcap"), h, data, &mut |r| {
            if let Record::Message { data, .. } = r {
                got.push(data.to_vec());
            }
            Ok(())
        })?;
        Ok(got)
    }

    #[test]
    fn chunks_unpack_plain_zstd_and_lz4_with_their_crc() {
        let raw = records_bytes();
        let crc = crc32fast::hash(&raw);
        let zstd = zstd::encode_all(raw.as_slice(), 3).unwrap();
        let mut lz4 = lz4::EncoderBuilder::new().build(Vec::new()).unwrap();
        lz4.write_all(&raw).unwrap();
        let (lz4, done) = lz4.finish();
        done.unwrap();
        for (compression, data) in [("", raw.clone()), ("zstd", zstd), ("lz4", lz4)] {
            let got = bodies(&header(compression, &raw, crc), &data).unwrap();
            assert_eq!(
                got,
                vec![b"first".to_vec(), b"second record".to_vec()],
                "{compression}"
            );
        }
    }

    #[test]
    fn a_damaged_chunk_is_an_error_not_a_panic() {
        let raw = records_bytes();
        let crc = crc32fast::hash(&raw);
        let mut flipped = raw.clone();
        flipped[40] ^= 1;
        let e = bodies(&header("", &raw, crc), &flipped)
            .unwrap_err()
            .to_string();
        assert!(e.contains("CRC"), "{e}");
        // A record claiming more than the chunk holds (mcap's own walk subtracts and wraps).
        let mut long = raw.clone();
        long[1] = 200;
        let e = bodies(&header("", &long, 0), &long)
            .unwrap_err()
            .to_string();
        assert!(e.contains("bytes where"), "{e}");
        let e = bodies(&header("", &raw[..5], 0), &raw[..5])
            .unwrap_err()
            .to_string();
        assert!(e.contains("inside a record's header"), "{e}");
        let e = bodies(&header("brotli", &raw, 0), &raw)
            .unwrap_err()
            .to_string();
        assert!(e.contains("brotli"), "{e}");
        // Decompressing to less than the header says.
        let mut h = header("zstd", &raw, 0);
        h.uncompressed_size += 10;
        let e = bodies(&h, &zstd::encode_all(raw.as_slice(), 3).unwrap())
            .unwrap_err()
            .to_string();
        assert!(e.contains("header says"), "{e}");
    }
}
