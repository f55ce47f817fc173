//! The Unix-domain-socket case: one stream connection, blocking
//! `write_all` / `read_exact` of the whole message each way.

use std::io::{Read, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::time::{Duration, Instant};

use crate::driver::{run_pinger, run_ponger, Served};
use crate::payload::Payload;
use crate::{socket_path, BenchError, PeerConfig, PeerReport, PongReport};

fn io_error(what: &'static str) -> impl Fn(std::io::Error) -> BenchError {
    move |e| match e.kind() {
        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut => BenchError::Io {
            what,
            source: "nothing arrived within the peer timeout".into(),
        },
        _ => BenchError::Io {
            what,
            source: Box::new(e),
        },
    }
}

/// Reads one whole message into `m`.
fn read_msg<M: Payload>(s: &mut UnixStream, m: &mut M) -> Result<(), BenchError> {
    s.read_exact(bytemuck::bytes_of_mut(m))
        .map_err(io_error("socket read"))
}

/// The pinger: connects (retrying until the ponger listens), then pings.
pub(crate) fn ping<M: Payload>(cfg: &PeerConfig) -> Result<PeerReport, BenchError> {
    let path = socket_path(&cfg.run_id, cfg.size);
    let timeout = cfg.timeout();
    let start = Instant::now();
    let mut stream = loop {
        match UnixStream::connect(&path) {
            Ok(s) => break s,
            Err(e) if start.elapsed() > timeout => {
                return Err(BenchError::setup(format!(
                    "a connection to {}",
                    path.display()
                ))(Box::new(e)))
            }
            Err(_) => std::thread::sleep(Duration::from_millis(2)),
        }
    };
    // A dead ponger ends the run with an error instead of a hang.
    stream
        .set_read_timeout(Some(timeout))
        .map_err(io_error("socket setup"))?;
    let mut reader = stream.try_clone().map_err(io_error("socket setup"))?;
    // One buffer each way, on the heap, reused: the message is written into
    // it and the socket copies it into the kernel and out again.
    let mut out: Box<M> = bytemuck::zeroed_box();
    let mut back: Box<M> = bytemuck::zeroed_box();
    run_pinger(
        cfg,
        M::SIZE,
        |round| {
            out.fill(round);
            stream
                .write_all(bytemuck::bytes_of(&*out))
                .map_err(io_error("socket write"))
        },
        |round, _limit| loop {
            // The stream is reliable: round 0 is sent once and always answered.
            read_msg(&mut reader, &mut *back)?;
            if back.round() == round {
                return Ok(Some(back.check(round)));
            }
        },
    )
}

/// The ponger: listens, accepts one connection, echoes until the stop.
pub(crate) fn pong<M: Payload>(cfg: &PeerConfig) -> Result<PongReport, BenchError> {
    let path = socket_path(&cfg.run_id, cfg.size);
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)
            .map_err(|e| BenchError::setup(dir.display().to_string())(Box::new(e)))?;
    }
    let _ = std::fs::remove_file(&path);
    let listener = UnixListener::bind(&path)
        .map_err(|e| BenchError::setup(path.display().to_string())(Box::new(e)))?;
    let result = serve::<M>(&listener, cfg.timeout(), cfg.warmup);
    let _ = std::fs::remove_file(&path);
    result
}

fn serve<M: Payload>(
    listener: &UnixListener,
    timeout: Duration,
    warmup: u64,
) -> Result<PongReport, BenchError> {
    listener
        .set_nonblocking(true)
        .map_err(io_error("socket setup"))?;
    let start = Instant::now();
    let mut stream = loop {
        match listener.accept() {
            Ok((s, _)) => break s,
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                if start.elapsed() > timeout {
                    return Err(BenchError::Timeout {
                        what: "the pinger's connection",
                        secs: timeout.as_secs_f64(),
                    });
                }
                std::thread::sleep(Duration::from_millis(2));
            }
            Err(e) => return Err(io_error("accept")(e)),
        }
    };
    stream
        .set_nonblocking(false)
        .map_err(io_error("socket setup"))?;
    stream
        .set_read_timeout(Some(timeout))
        .map_err(io_error("socket setup"))?;
    let mut buf: Box<M> = bytemuck::zeroed_box();
    run_ponger(warmup, || {
        read_msg(&mut stream, &mut *buf)?;
        let round = buf.round();
        if !buf.check(round) {
            return Err(BenchError::Corrupt { round });
        }
        buf.fill(round);
        stream
            .write_all(bytemuck::bytes_of(&*buf))
            .map_err(io_error("socket write"))?;
        let mut served = Served::default();
        served.add(round);
        Ok(served)
    })
}
