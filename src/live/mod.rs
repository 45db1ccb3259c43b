//! The live view of a run in a browser (`measure --live`): a small HTTP server and the page
//! it serves.
//!
//! Owns [`LiveServer`]. It binds (the loopback interface unless told otherwise) and serves,
//! each connection answered and closed:
//! - `GET /`: the page ([`PAGE`]), self-contained: nothing is loaded from elsewhere, so it
//!   works on a bench without internet;
//! - `GET /state?since=N`: the feed's [`LiveSnapshot`] as JSON, the points from number `N`
//!   on; the page asks ten times a second, so it survives being closed and reopened and
//!   any number of pages see the same run;
//! - `POST /stop`: the run stops as on Ctrl-C (motor stopped, recording kept and marked
//!   cancelled).
//!
//! Threads, like the rest of the host (ARCHITECTURE.md says why not async); a request that
//! is malformed, too large or too slow gets an error status or is dropped, never a panic.
//! It does not run the session or know the bench: what it shows is the session's
//! [`LiveFeed`].

use std::io::{ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream, ToSocketAddrs};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use crate::rig::session::live::{LiveFeed, LiveSnapshot};

/// The page: HTML, style and script in one file.
pub const PAGE: &str = include_str!("page.html");

/// Where `--live` binds without an address: the loopback interface, on a free port.
pub const DEFAULT_ADDR: &str = "127.0.0.1";

/// Longest request head read, bytes: 8 KiB, what common servers allow; the page's requests
/// are a few hundred.
const MAX_HEAD: usize = 8192;

/// Connections answered at once; more get `503` at once. 16: a few pages and scripts,
/// never enough threads to matter beside the session.
const MAX_CONNECTIONS: usize = 16;

/// A client that sends its request, or takes its answer, slower than this is dropped.
const IO_TIMEOUT: Duration = Duration::from_secs(2);

/// How often the accepting thread looks for a new connection and for its own stop.
const ACCEPT_POLL: Duration = Duration::from_millis(20);

/// Error starting the live view.
#[derive(Debug, thiserror::Error)]
pub enum LiveError {
    /// The address does not parse or resolve.
    #[error("--live {addr}: not an address to listen on ({message}); give HOST or HOST:PORT, e.g. 127.0.0.1:8080")]
    Address {
        /// As given.
        addr: String,
        /// Why.
        message: String,
    },
    /// The address cannot be bound (in use, not this machine's, no permission).
    #[error("--live {addr}: cannot listen there: {source}")]
    Bind {
        /// As resolved.
        addr: String,
        /// The system's reason.
        source: std::io::Error,
    },
}

/// A running live view; stopped when dropped.
pub struct LiveServer {
    addr: SocketAddr,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl LiveServer {
    /// Serve `feed` on `addr` (`HOST` or `HOST:PORT`; without a port, a free one).
    pub fn start(addr: &str, feed: Arc<LiveFeed>) -> Result<LiveServer, LiveError> {
        let bad = |message: String| LiveError::Address {
            addr: addr.to_string(),
            message,
        };
        let with_port = if addr.parse::<SocketAddr>().is_ok() || has_port(addr) {
            addr.to_string()
        } else if addr.contains(':') && !addr.starts_with('[') {
            // A bare IPv6 address.
            format!("[{addr}]:0")
        } else {
            // A name, an IPv4 address or a bracketed IPv6 address.
            format!("{addr}:0")
        };
        let resolved = with_port
            .to_socket_addrs()
            .map_err(|e| bad(e.to_string()))?
            .next()
            .ok_or_else(|| bad("it resolves to nothing".into()))?;
        let listener = TcpListener::bind(resolved).map_err(|source| LiveError::Bind {
            addr: resolved.to_string(),
            source,
        })?;
        let addr = listener.local_addr().map_err(|source| LiveError::Bind {
            addr: resolved.to_string(),
            source,
        })?;
        listener
            .set_nonblocking(true)
            .map_err(|source| LiveError::Bind {
                addr: addr.to_string(),
                source,
            })?;
        let stop = Arc::new(AtomicBool::new(false));
        let thread = {
            let stop = stop.clone();
            std::thread::Builder::new()
                .name("live-view".into())
                .spawn(move || accept_loop(listener, feed, stop))
                .map_err(|source| LiveError::Bind {
                    addr: addr.to_string(),
                    source,
                })?
        };
        Ok(LiveServer {
            addr,
            stop,
            thread: Some(thread),
        })
    }

    /// The address it listens on.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// The page's address, for a browser.
    pub fn url(&self) -> String {
        format!("http://{}/", self.addr)
    }

    /// Whether only this machine can reach it.
    pub fn is_loopback(&self) -> bool {
        self.addr.ip().is_loopback()
    }
}

impl Drop for LiveServer {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Whether `addr` ends in `:PORT` (a name or IPv4 address with a port, or `[v6]:port`).
fn has_port(addr: &str) -> bool {
    match addr.rsplit_once(':') {
        Some((host, port)) => {
            port.parse::<u16>().is_ok()
                && (!host.contains(':') || (host.starts_with('[') && host.ends_with(']')))
        }
        None => false,
    }
}

fn accept_loop(listener: TcpListener, feed: Arc<LiveFeed>, stop: Arc<AtomicBool>) {
    let busy = Arc::new(AtomicUsize::new(0));
    while !stop.load(Ordering::SeqCst) {
        match listener.accept() {
            Ok((stream, _)) => {
                if busy.fetch_add(1, Ordering::SeqCst) >= MAX_CONNECTIONS {
                    busy.fetch_sub(1, Ordering::SeqCst);
                    let _ = prepare(&stream).and_then(|_| {
                        respond(&stream, "503 Service Unavailable", "text/plain", b"busy\n")
                    });
                    continue;
                }
                let (feed, done) = (feed.clone(), busy.clone());
                let spawned = std::thread::Builder::new()
                    .name("live-request".into())
                    .spawn(move || {
                        let _ = serve(&stream, &feed);
                        done.fetch_sub(1, Ordering::SeqCst);
                    });
                if spawned.is_err() {
                    busy.fetch_sub(1, Ordering::SeqCst);
                }
            }
            Err(e) if e.kind() == ErrorKind::WouldBlock => std::thread::sleep(ACCEPT_POLL),
            Err(e) if e.kind() == ErrorKind::Interrupted => {}
            Err(e) => {
                tracing::warn!("live view: accepting a connection failed: {e}");
                std::thread::sleep(ACCEPT_POLL);
            }
        }
    }
}

/// Blocking I/O with timeouts on an accepted connection.
fn prepare(stream: &TcpStream) -> std::io::Result<()> {
    stream.set_nonblocking(false)?;
    stream.set_read_timeout(Some(IO_TIMEOUT))?;
    stream.set_write_timeout(Some(IO_TIMEOUT))
}

/// A request's method, path and query.
#[derive(Debug, PartialEq)]
struct Request {
    method: String,
    path: String,
    query: String,
}

/// Parse a request head (up to the blank line); `None` when it is not HTTP/1.
fn parse_head(head: &str) -> Option<Request> {
    let line = head.lines().next()?;
    let mut parts = line.split(' ');
    let (method, target, version) = (parts.next()?, parts.next()?, parts.next()?);
    if parts.next().is_some() || !version.starts_with("HTTP/1.") || !target.starts_with('/') {
        return None;
    }
    let (path, query) = target.split_once('?').unwrap_or((target, ""));
    Some(Request {
        method: method.to_string(),
        path: path.to_string(),
        query: query.to_string(),
    })
}

/// The value of `key` in a query string.
fn query_value<'a>(query: &'a str, key: &str) -> Option<&'a str> {
    query
        .split('&')
        .filter_map(|kv| kv.split_once('='))
        .find(|(k, _)| *k == key)
        .map(|(_, v)| v)
}

/// Read one request head from `stream`, or `None` when the client sends too much, too
/// slowly, or closes first.
fn read_head(mut stream: &TcpStream) -> Option<String> {
    let mut buf = Vec::with_capacity(512);
    let mut chunk = [0u8; 1024];
    loop {
        if let Some(end) = buf.windows(4).position(|w| w == b"\r\n\r\n") {
            return String::from_utf8(buf[..end].to_vec()).ok();
        }
        if buf.len() > MAX_HEAD {
            return None;
        }
        match stream.read(&mut chunk) {
            Ok(0) | Err(_) => return None,
            Ok(n) => buf.extend_from_slice(&chunk[..n]),
        }
    }
}

fn serve(stream: &TcpStream, feed: &LiveFeed) -> std::io::Result<()> {
    prepare(stream)?;
    let Some(head) = read_head(stream) else {
        return respond(stream, "400 Bad Request", "text/plain", b"bad request\n");
    };
    let Some(req) = parse_head(&head) else {
        return respond(stream, "400 Bad Request", "text/plain", b"bad request\n");
    };
    match (req.method.as_str(), req.path.as_str()) {
        ("GET", "/") | ("GET", "/index.html") => respond(
            stream,
            "200 OK",
            "text/html; charset=utf-8",
            PAGE.as_bytes(),
        ),
        ("GET", "/state") => {
            let since = match query_value(&req.query, "since").map(str::parse::<u64>) {
                None => 0,
                Some(Ok(n)) => n,
                Some(Err(_)) => {
                    return respond(
                        stream,
                        "400 Bad Request",
                        "text/plain",
                        b"since: a point number (0, 1, ...)\n",
                    )
                }
            };
            let body = state_json(&feed.snapshot(since));
            respond(stream, "200 OK", "application/json", body.as_bytes())
        }
        ("POST", "/stop") => {
            tracing::warn!("live view: stop requested from the page");
            feed.request_stop();
            respond(
                stream,
                "200 OK",
                "application/json",
                b"{\"stop_requested\":true}",
            )
        }
        (_, "/" | "/index.html" | "/state") => respond_allow(stream, "GET", "only GET here\n"),
        (_, "/stop") => respond_allow(stream, "POST", "only POST here\n"),
        _ => respond(stream, "404 Not Found", "text/plain", b"not found\n"),
    }
}

/// The snapshot as JSON (the types serialize plainly; a failure would be a bug, answered as
/// an empty object rather than a panic on the server's thread).
fn state_json(s: &LiveSnapshot) -> String {
    serde_json::to_string(s).unwrap_or_else(|_| "{}".into())
}

fn respond(
    mut stream: &TcpStream,
    status: &str,
    content_type: &str,
    body: &[u8],
) -> std::io::Result<()> {
    let head = format!(
        "HTTP/1.1 {status}\r\nContent-Type: {content_type}\r\nContent-Length: {}\r\n\
         Cache-Control: no-store\r\nConnection: close\r\n\r\n",
        body.len()
    );
    stream.write_all(head.as_bytes())?;
    stream.write_all(body)?;
    stream.flush()
}

fn respond_allow(mut stream: &TcpStream, allow: &str, body: &str) -> std::io::Result<()> {
    let head = format!(
        "HTTP/1.1 405 Method Not Allowed\r\nAllow: {allow}\r\nContent-Type: text/plain\r\n\
         Content-Length: {}\r\nConnection: close\r\n\r\n",
        body.len()
    );
    stream.write_all(head.as_bytes())?;
    stream.write_all(body.as_bytes())?;
    stream.flush()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rig::recording::Phase;
    use crate::rig::session::live::LiveStatus;

    /// A raw HTTP exchange: send `request`, return the whole answer.
    fn exchange(addr: SocketAddr, request: &[u8]) -> String {
        let mut s = TcpStream::connect(addr).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
        s.write_all(request).unwrap();
        let mut out = String::new();
        s.read_to_string(&mut out).unwrap();
        out
    }

    fn status_line(answer: &str) -> &str {
        answer.lines().next().unwrap_or("")
    }

    fn body(answer: &str) -> &str {
        answer.split_once("\r\n\r\n").map_or("", |(_, b)| b)
    }

    /// Guards the three routes and their errors, as a browser and a script meet them: the
    /// page, the state from a cursor (whole JSON text), the stop that cancels the run, and
    /// 400/404/405 for what is not asked right.
    #[test]
    fn routes_answer_and_errors_are_statuses() {
        let cancel = Arc::new(AtomicBool::new(false));
        let feed = LiveFeed::new(cancel.clone());
        feed.begin("half-turn-2to1", "1R");
        feed.sample(Phase::Forward, 1.0, None);
        feed.sample(Phase::Forward, 2.0, None);
        feed.status(LiveStatus {
            phase: "forward",
            cycle: 0.25,
            cycles: 3,
            samples: 250,
            sample_rate_hz: 1000.0,
            gaps: 0,
            error_deg: Some(0.125),
            driver_deg: 2.0,
            elapsed_s: 0.5,
        });
        let server = LiveServer::start("127.0.0.1", feed.clone()).unwrap();
        assert!(server.is_loopback());
        assert!(server.url().starts_with("http://127.0.0.1:"));
        let addr = server.addr();

        let page = exchange(addr, b"GET / HTTP/1.1\r\nHost: x\r\n\r\n");
        assert_eq!(status_line(&page), "HTTP/1.1 200 OK");
        assert!(body(&page).contains("<canvas"), "{page}");

        let state = exchange(addr, b"GET /state?since=1 HTTP/1.1\r\n\r\n");
        assert_eq!(status_line(&state), "HTTP/1.1 200 OK");
        assert_eq!(
            body(&state),
            "{\"target\":\"half-turn-2to1\",\"class\":\"1R\",\"status\":{\"phase\":\"forward\",\
             \"cycle\":0.25,\"cycles\":3,\"samples\":250,\"sample_rate_hz\":1000.0,\"gaps\":0,\
             \"error_deg\":0.125,\"driver_deg\":2.0,\"elapsed_s\":0.5},\"ended\":null,\
             \"stop_requested\":false,\"points\":[{\"seq\":1,\"phase\":\"forward\",\
             \"driver_deg\":2.0,\"error_deg\":null,\"aligned\":false,\"target_deg\":null,\
             \"follower_deg\":null}],\"next\":2}"
        );

        for (request, expected) in [
            (
                &b"GET /state?since=x HTTP/1.1\r\n\r\n"[..],
                "HTTP/1.1 400 Bad Request",
            ),
            (b"BREW / HTCPCP/1.0\r\n\r\n", "HTTP/1.1 400 Bad Request"),
            (b"GET /nowhere HTTP/1.1\r\n\r\n", "HTTP/1.1 404 Not Found"),
            (
                b"POST /state HTTP/1.1\r\n\r\n",
                "HTTP/1.1 405 Method Not Allowed",
            ),
            (
                b"GET /stop HTTP/1.1\r\n\r\n",
                "HTTP/1.1 405 Method Not Allowed",
            ),
        ] {
            assert_eq!(status_line(&exchange(addr, request)), expected);
        }
        assert!(!cancel.load(Ordering::SeqCst), "only POST /stop stops");

        let stop = exchange(addr, b"POST /stop HTTP/1.1\r\nContent-Length: 0\r\n\r\n");
        assert_eq!(status_line(&stop), "HTTP/1.1 200 OK");
        assert!(cancel.load(Ordering::SeqCst));
    }

    /// Guards the server against clients that misbehave: an oversized head, a client that
    /// connects and says nothing, bytes that are not text. Each is dropped or refused and
    /// the next request is still answered.
    #[test]
    fn bad_clients_do_not_stop_the_server() {
        let feed = LiveFeed::new(Arc::new(AtomicBool::new(false)));
        let server = LiveServer::start("127.0.0.1:0", feed).unwrap();
        let addr = server.addr();
        let huge = vec![b'a'; MAX_HEAD * 2];
        let mut s = TcpStream::connect(addr).unwrap();
        let _ = s.write_all(&huge);
        let silent = TcpStream::connect(addr).unwrap();
        let garbage = exchange(addr, b"\xff\xfe\x00\r\n\r\n");
        assert_eq!(status_line(&garbage), "HTTP/1.1 400 Bad Request");
        drop(silent);
        let ok = exchange(addr, b"GET /state HTTP/1.1\r\n\r\n");
        assert_eq!(status_line(&ok), "HTTP/1.1 200 OK");
    }

    /// Guards the address forms `--live` takes and the errors for the others.
    #[test]
    fn addresses_and_their_errors() {
        assert!(has_port("127.0.0.1:8080"));
        assert!(has_port("localhost:80"));
        assert!(has_port("[::1]:80"));
        assert!(!has_port("::1"));
        assert!(!has_port("[::1]"));
        assert!(!has_port("127.0.0.1"));
        let feed = LiveFeed::new(Arc::new(AtomicBool::new(false)));
        let e = LiveServer::start("127.0.0.1:notaport", feed.clone())
            .err()
            .unwrap()
            .to_string();
        assert!(
            e.starts_with("--live 127.0.0.1:notaport: not an address to listen on ("),
            "{e}"
        );
        assert!(
            e.ends_with("give HOST or HOST:PORT, e.g. 127.0.0.1:8080"),
            "{e}"
        );
        // A bracketed IPv6 address without a port is an address (binding it may still
        // fail where the machine has no IPv6).
        match LiveServer::start("[::1]", feed.clone()) {
            Ok(s) => assert!(s.is_loopback()),
            Err(e) => assert!(matches!(e, LiveError::Bind { .. }), "{e}"),
        }
        let taken = LiveServer::start("127.0.0.1", feed.clone()).unwrap();
        let e = LiveServer::start(&taken.addr().to_string(), feed)
            .err()
            .unwrap()
            .to_string();
        assert!(
            e.starts_with(&format!("--live {}: cannot listen there: ", taken.addr())),
            "{e}"
        );
    }
}
