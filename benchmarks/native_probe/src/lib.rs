//! The per-message work of plugcell's request path for one 4-byte `Echo`, in Rust: a
//! measuring device of `benchmarks/durability_floor.py --native`, not part of plugcell.
//!
//! [`Service::admit`] does what a service does with a published CreateProcess before the
//! device's handler (decode the envelope, check it as `framework/admission.py` does);
//! [`Service::complete`] what it does after (journal the process and its two updates as
//! one record of the journal's log, encode the acknowledgement and the `Completed` update
//! with the handler's output in one `ProcessUpdateBatch`, the same map layout msgspec
//! writes for plugcell); [`Service::answer`] both, with the input as the output.  [`Requester`] encodes the request and reads the
//! answer's final update.  It covers the one command the benchmark sends; anything else
//! is refused with the reason, as plugcell would.

use std::fs::{File, OpenOptions};
use std::io::Write;
use std::time::{SystemTime, UNIX_EPOCH};

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyBytes;
use rmp::encode as enc;
use rmpv::ValueRef;

type Pairs<'a> = [(ValueRef<'a>, ValueRef<'a>)];

const VERSION: u64 = 1;
const ECHO: &str = "Echo";

fn now_ns() -> u64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map(|d| d.as_nanos() as u64).unwrap_or(0)
}

fn refuse(reason: impl Into<String>) -> PyErr {
    PyValueError::new_err(reason.into())
}

fn field<'b, 'a>(map: &'b Pairs<'a>, key: &str) -> Option<&'b ValueRef<'a>> {
    map.iter()
        .find(|(k, _)| matches!(k, ValueRef::String(s) if s.as_str() == Some(key)))
        .map(|(_, v)| v)
}

fn map<'b, 'a>(map: &'b Pairs<'a>, key: &str) -> PyResult<&'b Pairs<'a>> {
    match field(map, key) {
        Some(ValueRef::Map(m)) => struct_keys(m, key),
        _ => Err(refuse(format!("invalid message: expected a map at `{key}`"))),
    }
}

/// A map that is a structure: every key a string (msgspec skips unknown ones unread).
fn struct_keys<'b, 'a>(map: &'b Pairs<'a>, at: &str) -> PyResult<&'b Pairs<'a>> {
    if map.iter().all(|(k, _)| matches!(k, ValueRef::String(_))) {
        Ok(map)
    } else {
        Err(refuse(format!("invalid message: a key of `{at}` is not a str")))
    }
}

fn text<'b>(map: &'b Pairs<'_>, key: &str) -> PyResult<&'b str> {
    match field(map, key) {
        Some(ValueRef::String(s)) => {
            s.as_str().ok_or_else(|| refuse(format!("invalid message: `{key}` is not UTF-8")))
        }
        _ => Err(refuse(format!("invalid message: expected a str at `{key}`"))),
    }
}

fn uint(map: &Pairs<'_>, key: &str) -> PyResult<u64> {
    match field(map, key) {
        Some(ValueRef::Integer(i)) => {
            i.as_u64().ok_or_else(|| refuse(format!("invalid message: `{key}` is negative")))
        }
        _ => Err(refuse(format!("invalid message: expected an int at `{key}`"))),
    }
}

/// The message a payload holds: its envelope's keys and values, or why there is none.
fn decode(payload: &[u8]) -> PyResult<Vec<(ValueRef<'_>, ValueRef<'_>)>> {
    let mut cursor = payload;
    let value = rmpv::decode::read_value_ref(&mut cursor)
        .map_err(|e| refuse(format!("malformed message: {e}")))?;
    if !cursor.is_empty() {
        return Err(refuse("malformed message: trailing bytes"));
    }
    match value {
        ValueRef::Map(m) => {
            struct_keys(&m, "$")?;
            Ok(m)
        }
        _ => Err(refuse("invalid message: expected a map")),
    }
}

/// A service or cell name (`Name` of framework/messages.py).
fn name<'b>(map: &'b Pairs<'_>, key: &str) -> PyResult<&'b str> {
    let value = text(map, key)?;
    let bytes = value.as_bytes();
    let ok = !bytes.is_empty()
        && bytes.len() <= 64
        && bytes[0].is_ascii_alphanumeric()
        && bytes.iter().all(|b| b.is_ascii_alphanumeric() || b"_.-".contains(b));
    if ok { Ok(value) } else { Err(refuse(format!("invalid message: `{key}` is not a name"))) }
}

/// Absent (the default), or text of at most `longest` characters.
fn optional_text(map: &Pairs<'_>, key: &str, longest: usize) -> PyResult<()> {
    if field(map, key).is_some() && text(map, key)?.chars().count() > longest {
        return Err(refuse(format!("invalid message: `{key}` is too long")));
    }
    Ok(())
}

/// Absent (the default, or None where `nil` is allowed), or one of `allowed`.
fn optional_choice(map: &Pairs<'_>, key: &str, allowed: &[&str], nil: bool) -> PyResult<()> {
    match field(map, key) {
        None => Ok(()),
        Some(ValueRef::Nil) if nil => Ok(()),
        Some(_) if allowed.contains(&text(map, key)?) => Ok(()),
        Some(_) => Err(refuse(format!("invalid message: `{key}` is not one of {allowed:?}"))),
    }
}

/// Absent, or an array of at most 8 integers within `lowest ..= 2³¹ − 1`.
fn optional_size(map: &Pairs<'_>, key: &str, lowest: i64) -> PyResult<Vec<u64>> {
    let dims = match field(map, key) {
        None => return Ok(vec![]),
        Some(ValueRef::Array(dims)) if dims.len() <= 8 => dims,
        _ => return Err(refuse(format!("invalid message: expected a size at `{key}`"))),
    };
    dims.iter()
        .map(|d| match d {
            ValueRef::Integer(i) => match i.as_i64() {
                Some(n) if (lowest..=i64::from(i32::MAX)).contains(&n) => Ok(n.max(0) as u64),
                _ => Err(refuse(format!("invalid message: a dimension of `{key}` is out of range"))),
            },
            _ => Err(refuse(format!("invalid message: expected an int in `{key}`"))),
        })
        .collect()
}

const DATA_TYPES: &[&str] = &["Boolean", "Byte", "Integer", "Double", "String"];

/// A catalogue entry as a request carries it (`Command` of framework/messages.py).
fn check_command(command: &Pairs<'_>) -> PyResult<()> {
    let name = text(command, "Name")?;
    if name.is_empty() || name.chars().count() > 64 {
        return Err(refuse("invalid message: `Name` must have 1 to 64 characters"));
    }
    for key in ["Option", "SuccessCode", "Info"] {
        optional_text(command, key, usize::MAX)?;
    }
    optional_choice(command, "Type", &["NoData", "SingleData", "MultipleData", "StopData"], false)?;
    for key in ["InputDataType", "OutputDataType"] {
        optional_choice(command, key, DATA_TYPES, true)?;
    }
    for key in ["InputDataSize", "OutputDataSize"] {
        optional_size(command, key, -1)?;
    }
    let timeout = match field(command, "Timeout") {
        None => 10.0,
        Some(ValueRef::F64(t)) => *t,
        Some(ValueRef::F32(t)) => f64::from(*t),
        Some(ValueRef::Integer(i)) => i.as_f64().unwrap_or(f64::NAN),
        _ => return Err(refuse("invalid message: expected a number at `Timeout`")),
    };
    if !(timeout > 0.0 && timeout <= 86400.0 * 365.0) {
        return Err(refuse("invalid message: `Timeout` out of range"));
    }
    Ok(())
}

/// The `Data` of a Byte buffer: its size and bytes.
fn byte_data<'b>(map: &'b Pairs<'_>, key: &str) -> PyResult<(Vec<u64>, &'b [u8])> {
    let data = self::map(map, key)?;
    optional_choice(data, "Type", DATA_TYPES, false)?;
    if text(data, "Type")? != "Byte" {
        return Err(refuse(format!("{ECHO} input: expected Byte data")));
    }
    if field(data, "Size").is_none() {
        return Err(refuse("invalid message: expected a size at `Size`"));
    }
    let size = optional_size(data, "Size", 0)?;
    let buffer = match field(data, "Buffer") {
        Some(ValueRef::Binary(b)) => *b,
        _ => return Err(refuse("invalid message: expected bytes at `Buffer`")),
    };
    if size.iter().product::<u64>() != buffer.len() as u64 {
        return Err(refuse(format!("{ECHO} input: {} bytes for size {size:?}", buffer.len())));
    }
    Ok((size, buffer))
}

/// `Byte[4] [7, 7, 7, 7]`: the journal's summary of small data (`framework/data.py`).
fn summary(size: &[u64], buffer: &[u8]) -> String {
    let dims: Vec<String> = size.iter().map(u64::to_string).collect();
    let head = format!("Byte[{}]", dims.join(", "));
    if buffer.len() > 16 {
        return head;
    }
    let values: Vec<String> = buffer.iter().map(u8::to_string).collect();
    format!("{head} [{}]", values.join(", "))
}

fn write_str(out: &mut Vec<u8>, s: &str) {
    enc::write_str(out, s).expect("writing to a Vec");
}

fn write_uint(out: &mut Vec<u8>, n: u64) {
    enc::write_uint(out, n).expect("writing to a Vec");
}

fn write_map(out: &mut Vec<u8>, len: u32) {
    enc::write_map_len(out, len).expect("writing to a Vec");
}

fn write_array(out: &mut Vec<u8>, len: u32) {
    enc::write_array_len(out, len).expect("writing to a Vec");
}

/// Keys with text values, in order (a part of a map whose length is written before).
fn write_texts(out: &mut Vec<u8>, pairs: &[(&str, &str)]) {
    for (key, value) in pairs {
        write_str(out, key);
        write_str(out, value);
    }
}

fn write_tag(out: &mut Vec<u8>, sender: &str, recipient: &str) {
    write_map(out, 2);
    write_texts(out, &[("Sender", sender), ("Recipient", recipient)]);
}

fn write_data(out: &mut Vec<u8>, size: &[u64], buffer: &[u8]) {
    write_map(out, 3);
    write_texts(out, &[("Type", "Byte")]);
    write_str(out, "Size");
    write_array(out, size.len() as u32);
    for d in size {
        write_uint(out, *d);
    }
    write_str(out, "Buffer");
    enc::write_bin(out, buffer).expect("writing to a Vec");
}

/// The envelope's head and the start of its `Body`: a map of `fields` entries, the
/// first `"Kind": kind`; the body's other entries follow.
fn write_envelope(out: &mut Vec<u8>, sender: &str, instance: &str, kind: &str, fields: u32) {
    write_map(out, 5);
    write_str(out, "V");
    write_uint(out, VERSION);
    write_texts(out, &[("Sender", sender), ("Instance", instance)]);
    write_str(out, "TimeNs");
    write_uint(out, now_ns());
    write_str(out, "Body");
    write_map(out, fields);
    write_texts(out, &[("Kind", kind)]);
}

/// The answering side: one service with the catalogue entry `Echo` (Byte in, Byte out).
#[pyclass]
struct Service {
    owner: String,
    instance: String,
    log: Option<File>,
}

#[pymethods]
impl Service {
    /// `log`: the journal's log file to append each request's record to (None: none).
    #[new]
    #[pyo3(signature = (owner, instance, log=None))]
    fn new(owner: String, instance: String, log: Option<String>) -> PyResult<Self> {
        let log = match log {
            Some(path) => {
                let fail = |e: std::io::Error| refuse(format!("{path}: {e}"));
                let mut file =
                    OpenOptions::new().create(true).append(true).open(&path).map_err(fail)?;
                if file.metadata().map_err(fail)?.len() == 0 {
                    // the log's header (framework/journal_log.py): magic, generation
                    let mut header = b"PCJLOG01".to_vec();
                    header.extend_from_slice(&now_ns().to_le_bytes());
                    file.write_all(&header).map_err(fail)?;
                }
                Some(file)
            }
            None => None,
        };
        Ok(Service { owner, instance, log })
    }

    /// Admit a CreateProcess published by `published_by`, journal it, and return the
    /// batch that acknowledges and completes it with its own input as the output (what
    /// `Echo` does); ValueError with the reason otherwise.
    fn answer<'py>(
        &mut self,
        py: Python<'py>,
        payload: &[u8],
        published_by: &str,
    ) -> PyResult<Bound<'py, PyBytes>> {
        let admitted = self.admit(payload, published_by)?;
        self.complete(py, &admitted, &admitted.input)
    }

    /// Decode and check a CreateProcess published by `published_by` as plugcell's
    /// admission does: the process, for [`Service::complete`] after the device's handler
    /// ran; ValueError with the reason if it is refused.
    fn admit(&self, payload: &[u8], published_by: &str) -> PyResult<Admitted> {
        let received = now_ns();
        let envelope = decode(payload)?;
        let envelope = envelope.as_slice();
        let version = uint(envelope, "V")?;
        if version != VERSION {
            return Err(refuse(format!("unsupported protocol version {version}")));
        }
        let sender = name(envelope, "Sender")?;
        if sender != published_by {
            return Err(refuse(format!(
                "envelope sender {sender} differs from the sender {published_by} of the request key"
            )));
        }
        let sender_instance = text(envelope, "Instance")?;
        optional_text(envelope, "Instance", 64)?;
        if !matches!(field(envelope, "TimeNs"), Some(ValueRef::Integer(_))) {
            return Err(refuse("invalid message: expected an int at `TimeNs`"));
        }
        if !matches!(field(envelope, "Auth"), None | Some(ValueRef::Nil)) {
            return Err(refuse("signed requests are not measured by this probe"));
        }
        let body = map(envelope, "Body")?;
        let kind = text(body, "Kind")?;
        if kind != "Process" {
            return Err(refuse(format!("expected a Process, got {kind}")));
        }
        let tag = map(body, "Tag")?;
        let (tag_sender, recipient) = (name(tag, "Sender")?, name(tag, "Recipient")?);
        if recipient != self.owner {
            return Err(refuse(format!("process addressed to {recipient}, this is {}", self.owner)));
        }
        if tag_sender != sender {
            return Err(refuse(format!(
                "tag sender {tag_sender} differs from the envelope sender {sender}"
            )));
        }
        optional_choice(body, "State", &["Queued", "Running", "Completed", "Failed"], false)?;
        let command = map(body, "Command")?;
        check_command(command)?;
        let name = text(command, "Name")?;
        if name != ECHO {
            return Err(refuse(format!(
                "unknown command '{name}' for {} (commands: {ECHO})",
                self.owner
            )));
        }
        let option = if field(command, "Option").is_some() { text(command, "Option")? } else { "" };
        let identifier = uint(body, "Identifier")?;
        if identifier == 0 || identifier > i64::MAX as u64 {
            return Err(refuse("invalid message: `Identifier` out of range"));
        }
        let (size, buffer) = byte_data(body, "Data")?;
        Ok(Admitted {
            sender: sender.to_owned(),
            sender_instance: sender_instance.to_owned(),
            option: option.to_owned(),
            identifier,
            received,
            summary: summary(&size, buffer),
            input: buffer.to_vec(),
        })
    }

    /// Journal `admitted` (its process row, Running and Completed updates: one record of
    /// the log) and return the batch that acknowledges it and completes it with `output`
    /// (Byte data of one dimension).
    fn complete<'py>(
        &mut self,
        py: Python<'py>,
        admitted: &Admitted,
        output: &[u8],
    ) -> PyResult<Bound<'py, PyBytes>> {
        let (sender, identifier) = (admitted.sender.as_str(), admitted.identifier);
        let size = [output.len() as u64];
        if let Some(log) = self.log.as_mut() {
            let described = summary(&size, output);
            let mut rows = Vec::with_capacity(256);
            write_array(&mut rows, 3);
            let now = now_ns();
            write_array(&mut rows, 2); // [0, process row]
            write_uint(&mut rows, 0);
            write_array(&mut rows, 13);
            for s in [self.owner.as_str(), sender] {
                write_str(&mut rows, s);
            }
            write_uint(&mut rows, identifier);
            for s in [self.instance.as_str(), &admitted.sender_instance, ECHO, &admitted.option,
                      "SingleData"] {
                write_str(&mut rows, s);
            }
            write_str(&mut rows, &admitted.summary);
            write_uint(&mut rows, admitted.received);
            write_uint(&mut rows, now);
            write_str(&mut rows, "Queued");
            write_str(&mut rows, "");
            for (seq, state, data) in [(1, "Running", ""), (2, "Completed", described.as_str())] {
                write_array(&mut rows, 2); // [1, update row]
                write_uint(&mut rows, 1);
                write_array(&mut rows, 8);
                write_str(&mut rows, &self.owner);
                write_str(&mut rows, sender);
                write_uint(&mut rows, identifier);
                write_uint(&mut rows, seq);
                write_uint(&mut rows, now);
                write_str(&mut rows, state);
                write_str(&mut rows, "");
                write_str(&mut rows, data);
            }
            let mut record = Vec::with_capacity(rows.len() + 8);
            record.extend_from_slice(&(rows.len() as u32).to_le_bytes());
            record.extend_from_slice(&crc32fast::hash(&rows).to_le_bytes());
            record.extend_from_slice(&rows);
            log.write_all(&record).map_err(|e| refuse(format!("journal: {e}")))?;
        }

        let mut out = Vec::with_capacity(256 + output.len());
        write_envelope(&mut out, &self.owner, &self.instance, "ProcessUpdateBatch", 3);
        write_str(&mut out, "Acks");
        write_array(&mut out, 1);
        write_map(&mut out, 5);
        write_texts(&mut out, &[("Kind", "Acknowledgement")]);
        write_str(&mut out, "Identifier");
        write_uint(&mut out, identifier);
        write_texts(&mut out, &[("State", "Queued"), ("Reason", ""), ("Instance", &self.instance)]);
        write_str(&mut out, "Updates");
        write_array(&mut out, 1);
        write_map(&mut out, 7);
        write_texts(&mut out, &[("Kind", "ProcessUpdateNotification")]);
        write_str(&mut out, "Tag");
        write_tag(&mut out, sender, &self.owner);
        write_str(&mut out, "Identifier");
        write_uint(&mut out, identifier);
        write_texts(&mut out, &[("State", "Completed")]);
        write_str(&mut out, "Data");
        write_data(&mut out, &size, output);
        write_texts(&mut out, &[("Reason", "")]);
        write_str(&mut out, "Seq");
        write_uint(&mut out, 2);
        Ok(PyBytes::new(py, &out))
    }
}

/// A CreateProcess that [`Service::admit`] accepted: what its journal rows and its answer
/// need, and its input for the device's handler.
#[pyclass(frozen)]
struct Admitted {
    sender: String,
    sender_instance: String,
    option: String,
    #[pyo3(get)]
    identifier: u64,
    received: u64,
    summary: String,
    input: Vec<u8>,
}

#[pymethods]
impl Admitted {
    /// The input data's bytes (Byte elements).
    #[getter]
    fn input<'py>(&self, py: Python<'py>) -> Bound<'py, PyBytes> {
        PyBytes::new(py, &self.input)
    }
}

/// The requesting side: `Echo` CreateProcesses to one service, one at a time.
#[pyclass]
struct Requester {
    sender: String,
    instance: String,
    recipient: String,
    identifier: u64,
}

#[pymethods]
impl Requester {
    #[new]
    fn new(sender: String, instance: String, recipient: String) -> Self {
        Requester { sender, instance, recipient, identifier: 0 }
    }

    /// The next request carrying `value` (Byte data): its payload and its attachment.
    fn request<'py>(
        &mut self,
        py: Python<'py>,
        value: &[u8],
    ) -> (Bound<'py, PyBytes>, Bound<'py, PyBytes>) {
        self.identifier += 1;
        let mut out = Vec::with_capacity(384 + value.len());
        write_envelope(&mut out, &self.sender, &self.instance, "Process", 6);
        write_str(&mut out, "Command");
        write_map(&mut out, 10);
        write_texts(&mut out, &[("Name", ECHO), ("Option", ""), ("SuccessCode", "OK"),
                                ("Type", "SingleData"), ("InputDataType", "Byte")]);
        write_str(&mut out, "InputDataSize");
        write_array(&mut out, 0);
        write_texts(&mut out, &[("OutputDataType", "Byte")]);
        write_str(&mut out, "OutputDataSize");
        write_array(&mut out, 0);
        write_str(&mut out, "Timeout");
        enc::write_f64(&mut out, 10.0).expect("writing to a Vec");
        write_texts(&mut out, &[("Info", "return the input data")]);
        write_str(&mut out, "Tag");
        write_tag(&mut out, &self.sender, &self.recipient);
        write_str(&mut out, "Identifier");
        write_uint(&mut out, self.identifier);
        write_texts(&mut out, &[("State", "Queued")]);
        write_str(&mut out, "Data");
        write_data(&mut out, &[value.len() as u64], value);
        (PyBytes::new(py, &out), PyBytes::new(py, &self.identifier.to_le_bytes()))
    }

    /// Whether `payload` holds the last request's final update (ValueError if it refused
    /// the request or is not a message).
    fn is_final(&self, payload: &[u8]) -> PyResult<bool> {
        let envelope = decode(payload)?;
        let body = map(&envelope, "Body")?;
        let lists = |key: &str| match field(body, key) {
            Some(ValueRef::Array(items)) => items.as_slice(),
            _ => &[],
        };
        for ack in lists("Acks") {
            if let ValueRef::Map(ack) = ack {
                if uint(ack, "Identifier")? == self.identifier && text(ack, "State")? == "Failed" {
                    return Err(refuse(format!("request refused: {}", text(ack, "Reason")?)));
                }
            }
        }
        for update in lists("Updates") {
            if let ValueRef::Map(update) = update {
                if uint(update, "Identifier")? == self.identifier
                    && text(update, "State")? == "Completed"
                {
                    byte_data(update, "Data")?;
                    return Ok(true);
                }
            }
        }
        Ok(false)
    }
}

#[pymodule]
fn plugcell_native_probe(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Service>()?;
    m.add_class::<Requester>()?;
    m.add_class::<Admitted>()?;
    Ok(())
}
