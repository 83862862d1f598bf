//! The bare UDP echo of benchmarks/rsi_latency.py in Rust (std only): `recv_from` ->
//! `send_to` of the part of each datagram that carries its sequence number, the floor of
//! a native cycle loop beside plugcell's link and the Python echo in the same run.
//!
//! Usage: plugcell_native_echo (--tail N | --first-field) [--mlock]
//!
//! * `--tail N`: answer the datagram's last N bytes (RSI: the tail carries the IPOC);
//! * `--first-field`: answer the first field of a protobuf message, tag and one length
//!   byte included, `data[..2 + data[1]]` (EGM: the header carries the seqno).
//!
//! Protocol with the benchmark (stdin/stdout, lines), the Python echo's:
//! `READY <port> <note>` once bound; the first line on stdin ends the warm-up (the times
//! so far are forgotten, the counters start); the second asks for the report, one JSON
//! line: `cpu_s` (the process's CPU time, /proc/self/task/*/schedstat), `wall_s`,
//! `in_out_ns` (packet in -> answer out of every datagram answered), `thread` (the
//! answering thread's page faults and context switches, /proc).  The answering thread
//! is the main thread (its id is the process id), so the benchmark gives it the same
//! scheduling as the other sensors' from outside (sched_setscheduler, sched_setaffinity).

use std::io::{BufRead, Write};
use std::net::UdpSocket;
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// What of a datagram the echo sends back.
#[derive(Clone, Copy)]
enum Part {
    Tail(usize),
    FirstField,
}

impl Part {
    fn of<'a>(&self, data: &'a [u8]) -> &'a [u8] {
        match *self {
            Part::Tail(n) => &data[data.len().saturating_sub(n)..],
            Part::FirstField => {
                let end = if data.len() >= 2 { 2 + data[1] as usize } else { data.len() };
                &data[..end.min(data.len())]
            }
        }
    }
}

extern "C" {
    fn mlockall(flags: i32) -> i32;
}

fn parse_args() -> Result<(Part, bool), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (mut part, mut mlock, mut i) = (None, false, 0);
    while i < args.len() {
        match args[i].as_str() {
            "--tail" => {
                let n = args.get(i + 1).ok_or("--tail needs a byte count")?;
                let n: usize = n.parse().map_err(|_| format!("--tail {n:?}: not a byte count"))?;
                part = Some(Part::Tail(n));
                i += 1;
            }
            "--first-field" => part = Some(Part::FirstField),
            "--mlock" => mlock = true,
            other => return Err(format!("unknown argument {other:?}")),
        }
        i += 1;
    }
    Ok((part.ok_or("give --tail N or --first-field")?, mlock))
}

/// The process's CPU time so far (ns): the sum of its threads' run time.
fn cpu_ns() -> u64 {
    let mut total = 0;
    if let Ok(tasks) = std::fs::read_dir("/proc/self/task") {
        for task in tasks.flatten() {
            if let Ok(s) = std::fs::read_to_string(task.path().join("schedstat")) {
                total += s.split_whitespace().next().and_then(|v| v.parse().ok()).unwrap_or(0);
            }
        }
    }
    total
}

/// The answering (main) thread's counters: minflt, majflt, voluntary, forced.
fn counters(tid: u32) -> Vec<(&'static str, i64)> {
    let mut out = Vec::new();
    if let Ok(stat) = std::fs::read_to_string(format!("/proc/self/task/{tid}/stat")) {
        if let Some((_, rest)) = stat.rsplit_once(')') {
            let f: Vec<&str> = rest.split_whitespace().collect();
            if f.len() > 9 {
                out.push(("minflt", f[7].parse().unwrap_or(0)));
                out.push(("majflt", f[9].parse().unwrap_or(0)));
            }
        }
    }
    if let Ok(status) = std::fs::read_to_string(format!("/proc/self/task/{tid}/status")) {
        for line in status.lines() {
            let value = || line.split_whitespace().nth(1).and_then(|v| v.parse().ok());
            if line.starts_with("voluntary_ctxt_switches") {
                out.push(("voluntary", value().unwrap_or(0)));
            } else if line.starts_with("nonvoluntary_ctxt_switches") {
                out.push(("forced", value().unwrap_or(0)));
            }
        }
    }
    out
}

fn main() {
    let (part, mlock) = match parse_args() {
        Ok(v) => v,
        Err(e) => {
            eprintln!("plugcell_native_echo: {e}");
            std::process::exit(2);
        }
    };
    let mut note = String::from("native echo");
    if mlock {
        // MCL_CURRENT | MCL_FUTURE (linux/mman.h)
        let ok = unsafe { mlockall(1 | 2) } == 0;
        note += if ok { ", memory locked" } else { ", memory not locked (see ulimit -l)" };
    }
    let sock = UdpSocket::bind("127.0.0.1:0").expect("bind a UDP port on 127.0.0.1");
    let port = sock.local_addr().expect("the bound address").port();
    let tid = std::process::id();
    // (packet in, in -> out ns) of every datagram answered: the report keeps those that came
    // in after the warm-up ended (one answered just before "go" may be recorded just after)
    let times: Arc<Mutex<Vec<(Instant, u64)>>> =
        Arc::new(Mutex::new(Vec::with_capacity(1 << 20)));
    let control = Arc::clone(&times);
    std::thread::spawn(move || {
        let stdin = std::io::stdin();
        let mut line = String::new();
        stdin.lock().read_line(&mut line).ok(); // the warm-up is over
        let (c0, cpu0, t0) = (counters(tid), cpu_ns(), Instant::now());
        control.lock().unwrap().clear();
        line.clear();
        stdin.lock().read_line(&mut line).ok(); // report
        let (cpu, wall) = (cpu_ns() - cpu0, t0.elapsed().as_secs_f64());
        let c1 = counters(tid);
        let mut thread: Vec<String> = c1.iter().map(|(k, v)| {
            let before = c0.iter().find(|(k0, _)| k0 == k).map_or(0, |(_, v0)| *v0);
            format!("\"{k}\": {}", v - before)
        }).collect();
        // no collector here: the Python echo's columns, zero by construction
        thread.push("\"collections\": 0, \"longest_collection_ns\": 0".into());
        let io: Vec<String> = control.lock().unwrap().iter()
            .filter(|(t_in, _)| *t_in >= t0).map(|(_, took)| took.to_string()).collect();
        let mut out = std::io::stdout().lock();
        writeln!(out, "{{\"cpu_s\": {}, \"wall_s\": {wall}, \"in_out_ns\": [{}], \"thread\": {{{}}}}}",
                 cpu as f64 / 1e9, io.join(", "), thread.join(", ")).ok();
        out.flush().ok();
        std::process::exit(0);
    });
    {
        let mut out = std::io::stdout().lock();
        writeln!(out, "READY {port} {note}").ok();
        out.flush().ok();
    }
    let mut buf = [0u8; 65535];
    loop {
        let (n, addr) = match sock.recv_from(&mut buf) {
            Ok(got) => got,
            Err(_) => continue,
        };
        let t_in = Instant::now();
        sock.send_to(part.of(&buf[..n]), addr).ok();
        let took = t_in.elapsed().as_nanos() as u64;
        times.lock().unwrap().push((t_in, took));
    }
}
