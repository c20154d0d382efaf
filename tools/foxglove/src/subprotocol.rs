//! Clients of both names of Foxglove's WebSocket protocol.
//!
//! The protocol's specification (<https://github.com/foxglove/ws-protocol>, `docs/spec.md`,
//! "Protocol overview") has the client offer subprotocols in the WebSocket handshake
//! (`Sec-WebSocket-Protocol`, RFC 6455 section 4) and the server select one it is compatible
//! with; it names the protocol `foxglove.websocket.v1`, which Lichtblick, the ws-protocol
//! libraries and older Foxglove apps offer. Foxglove's SDK (`foxglove` 0.30.3,
//! `src/websocket/handshake.rs`) negotiates only its own names for it, `foxglove.sdk.v1` and
//! `foxglove.sdk.v1.1` (the latter with a per-connection schema table), answers anything
//! else with HTTP 400, and has no option to add a name. Foxglove states that
//! `foxglove.sdk.v1` is the same protocol as `foxglove.websocket.v1` under a new name
//! (github.com/orgs/foxglove/discussions/1131, as cited by Lichtblick's pull request 819,
//! which added the new name beside the old one).
//!
//! So a [`Front`] listens on the public address and passes every connection through to the
//! SDK's server on a private loopback port. A handshake that offers an SDK name is passed on
//! untouched (the SDK chooses); one that offers only `foxglove.websocket.v1` is passed on
//! offering `foxglove.sdk.v1` instead, and the server's answer is passed back naming
//! `foxglove.websocket.v1`, the subprotocol the client asked for (the handshake's
//! `Sec-WebSocket-Accept` depends on the client's key only, RFC 6455 section 4.2.2, so it
//! stays valid). After the handshake the bytes are copied both ways unchanged.

use std::io::{self, Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::time::Duration;

use anyhow::Context as _;

/// The ws-protocol specification's name of the protocol.
pub const WEBSOCKET_V1: &str = "foxglove.websocket.v1";
/// The SDK's name of the same protocol.
pub const SDK_V1: &str = "foxglove.sdk.v1";
/// The SDK's name of the protocol with schema tables.
pub const SDK_V1_1: &str = "foxglove.sdk.v1.1";
/// The largest handshake head read (request or response); a longer one closes the connection.
pub const MAX_HEAD: usize = 16 * 1024;
/// How long a client may take to send its handshake.
pub const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(10);

/// The public listener, passing connections to the SDK's server.
pub struct Front {
    listener: TcpListener,
    backend: SocketAddr,
}

impl Front {
    /// Listens on `host:port` (port 0: any free port) for the server at `backend`.
    pub fn bind(host: &str, port: u16, backend: SocketAddr) -> anyhow::Result<Self> {
        let listener = TcpListener::bind((host, port))
            .with_context(|| format!("cannot listen on {host}:{port}"))?;
        Ok(Self { listener, backend })
    }

    /// The port listened on.
    pub fn port(&self) -> io::Result<u16> {
        Ok(self.listener.local_addr()?.port())
    }

    /// Accepts connections on a thread of its own, for the life of the process; each is
    /// served on its own threads. A connection that fails is closed and logged.
    pub fn spawn(self) -> io::Result<()> {
        std::thread::Builder::new()
            .name("ws-front".into())
            .spawn(move || {
                for client in self.listener.incoming() {
                    let Ok(client) = client else { continue };
                    let backend = self.backend;
                    let spawned =
                        std::thread::Builder::new()
                            .name("ws-conn".into())
                            .spawn(move || {
                                if let Err(e) = pass(client, backend) {
                                    tracing::debug!("connection closed: {e}");
                                }
                            });
                    if let Err(e) = spawned {
                        tracing::warn!("warning: connection refused: {e}");
                    }
                }
            })?;
        Ok(())
    }
}

/// Passes one connection through: the handshake (renamed if needed), then bytes both ways.
fn pass(mut client: TcpStream, backend: SocketAddr) -> io::Result<()> {
    client.set_read_timeout(Some(HANDSHAKE_TIMEOUT))?;
    let (head, rest) = read_head(&mut client)?;
    client.set_read_timeout(None)?;
    let (request, renamed) = rename_request(&head);
    let mut server = TcpStream::connect(backend)?;
    server.write_all(request.as_bytes())?;
    server.write_all(&rest)?;
    if renamed {
        let (head, rest) = read_head(&mut server)?;
        client.write_all(rename_response(&head).as_bytes())?;
        client.write_all(&rest)?;
    }
    let (mut c_read, mut s_write) = (client.try_clone()?, server.try_clone()?);
    let upstream = std::thread::Builder::new()
        .name("ws-up".into())
        .spawn(move || {
            let _ = io::copy(&mut c_read, &mut s_write);
            let _ = s_write.shutdown(Shutdown::Write);
        })?;
    let _ = io::copy(&mut server, &mut client);
    let _ = client.shutdown(Shutdown::Both);
    let _ = upstream.join();
    Ok(())
}

/// Reads an HTTP head (up to its blank line) and returns it with the bytes read past it.
fn read_head(stream: &mut TcpStream) -> io::Result<(String, Vec<u8>)> {
    let mut buf = Vec::with_capacity(1024);
    let mut chunk = [0u8; 1024];
    loop {
        if let Some(end) = buf.windows(4).position(|w| w == b"\r\n\r\n") {
            let rest = buf.split_off(end + 4);
            let head = String::from_utf8(buf)
                .map_err(|_| io::Error::new(io::ErrorKind::InvalidData, "head not UTF-8"))?;
            return Ok((head, rest));
        }
        if buf.len() > MAX_HEAD {
            return Err(io::Error::new(io::ErrorKind::InvalidData, "head too long"));
        }
        let n = stream.read(&mut chunk)?;
        if n == 0 {
            return Err(io::ErrorKind::UnexpectedEof.into());
        }
        buf.extend_from_slice(&chunk[..n]);
    }
}

/// Whether `line` is a `Sec-WebSocket-Protocol` header; its value if so.
fn protocol_header(line: &str) -> Option<&str> {
    let (name, value) = line.split_once(':')?;
    name.trim()
        .eq_ignore_ascii_case("sec-websocket-protocol")
        .then_some(value)
}

/// The request head to send the SDK's server, and whether `foxglove.websocket.v1` was
/// renamed `foxglove.sdk.v1` in it (only when no SDK name is offered).
pub fn rename_request(head: &str) -> (String, bool) {
    let offered: Vec<&str> = head
        .split("\r\n")
        .filter_map(protocol_header)
        .flat_map(|v| v.split(','))
        .map(str::trim)
        .collect();
    let rename =
        offered.contains(&WEBSOCKET_V1) && !offered.iter().any(|p| *p == SDK_V1 || *p == SDK_V1_1);
    if !rename {
        return (head.to_owned(), false);
    }
    let mut out = String::with_capacity(head.len());
    for line in head.trim_end_matches("\r\n").split("\r\n") {
        if protocol_header(line).is_none() {
            out.push_str(line);
            out.push_str("\r\n");
        }
    }
    out.push_str(&format!("Sec-WebSocket-Protocol: {SDK_V1}\r\n\r\n"));
    (out, true)
}

/// The SDK's response head with the subprotocol it selected named as the client offered it.
pub fn rename_response(head: &str) -> String {
    head.split("\r\n")
        .map(|line| match protocol_header(line) {
            Some(v) if v.trim() == SDK_V1 => format!("Sec-WebSocket-Protocol: {WEBSOCKET_V1}"),
            _ => line.to_owned(),
        })
        .collect::<Vec<_>>()
        .join("\r\n")
}

#[cfg(test)]
mod tests {
    use super::*;

    const REQUEST: &str = "GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\n";

    #[test]
    fn only_a_v1_only_offer_is_renamed() {
        let head = format!("{REQUEST}Sec-WebSocket-Protocol: foxglove.websocket.v1\r\n\r\n");
        let (out, renamed) = rename_request(&head);
        assert!(renamed);
        assert_eq!(
            out,
            format!("{REQUEST}Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n")
        );
        for offer in [
            "foxglove.sdk.v1",
            "foxglove.websocket.v1, foxglove.sdk.v1.1",
            "other",
        ] {
            let head = format!("{REQUEST}sec-websocket-protocol: {offer}\r\n\r\n");
            assert_eq!(rename_request(&head), (head.clone(), false), "{offer}");
        }
    }

    #[test]
    fn the_answer_names_what_the_client_offered() {
        let head = "HTTP/1.1 101 Switching Protocols\r\nsec-websocket-protocol: foxglove.sdk.v1\r\nX: y\r\n\r\n";
        assert_eq!(
            rename_response(head),
            "HTTP/1.1 101 Switching Protocols\r\nSec-WebSocket-Protocol: foxglove.websocket.v1\r\nX: y\r\n\r\n"
        );
    }
}
