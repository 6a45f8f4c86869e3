//! The WebSocket (RFC 6455) that the Foxglove protocol rides on: the opening handshake and the
//! frames, on a blocking `TcpStream` with short timeouts. Written out because a server that only
//! ever sends whole messages and reads small text needs little of a WebSocket library.

use std::io::{self, Read, Write};
use std::net::TcpStream;

const GUID: &str = "258EAFA5-E914-47DA-95CA-C5AB0DC85B11";
/// The subprotocol Foxglove asks for.
pub const SUBPROTOCOL: &str = "foxglove.websocket.v1";
/// No client message comes near this (subscribe lists).
const MAX_CLIENT_FRAME: u64 = 1 << 20;

/// Standard base64 with padding.
pub fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for c in bytes.chunks(3) {
        let n = (c[0] as u32) << 16
            | (*c.get(1).unwrap_or(&0) as u32) << 8
            | *c.get(2).unwrap_or(&0) as u32;
        for k in 0..4 {
            if k <= c.len() {
                out.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// `Sec-WebSocket-Accept` for a client's key.
pub fn accept_key(key: &str) -> String {
    let mut h = sha1_smol::Sha1::new();
    h.update(key.trim().as_bytes());
    h.update(GUID.as_bytes());
    base64(&h.digest().bytes())
}

/// Reads the client's HTTP upgrade request and answers it; `Err` says why it is not one.
pub fn handshake(s: &mut TcpStream) -> io::Result<()> {
    let mut req = Vec::new();
    let mut b = [0u8; 1];
    while !req.ends_with(b"\r\n\r\n") {
        if req.len() > 16 * 1024 || s.read(&mut b)? == 0 {
            return Err(io::Error::other("not an HTTP request"));
        }
        req.push(b[0]);
    }
    let req = String::from_utf8_lossy(&req);
    let header = |name: &str| {
        req.lines().find_map(|l| {
            let (k, v) = l.split_once(':')?;
            k.trim()
                .eq_ignore_ascii_case(name)
                .then(|| v.trim().to_string())
        })
    };
    let Some(key) = header("sec-websocket-key") else {
        let body = "chaosd serves the Foxglove WebSocket protocol here: open it in Foxglove (Open connection → Foxglove WebSocket)\n";
        let _ = write!(
            s,
            "HTTP/1.1 426 Upgrade Required\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
            body.len()
        );
        return Err(io::Error::other("a plain HTTP request"));
    };
    let proto = match header("sec-websocket-protocol") {
        Some(p) if p.split(',').any(|x| x.trim() == SUBPROTOCOL) => {
            format!("Sec-WebSocket-Protocol: {SUBPROTOCOL}\r\n")
        }
        _ => String::new(),
    };
    write!(
        s,
        "HTTP/1.1 101 Switching Protocols\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Accept: {}\r\n{proto}\r\n",
        accept_key(&key)
    )
}

/// Frame opcodes.
pub const TEXT: u8 = 1;
pub const BINARY: u8 = 2;
pub const CLOSE: u8 = 8;
pub const PING: u8 = 9;
pub const PONG: u8 = 10;

/// Appends one whole unmasked frame (a server's) to `out`.
pub fn frame(out: &mut Vec<u8>, opcode: u8, parts: &[&[u8]]) {
    let len: usize = parts.iter().map(|p| p.len()).sum();
    out.push(0x80 | opcode);
    match len {
        0..=125 => out.push(len as u8),
        126..=0xffff => {
            out.push(126);
            out.extend_from_slice(&(len as u16).to_be_bytes());
        }
        _ => {
            out.push(127);
            out.extend_from_slice(&(len as u64).to_be_bytes());
        }
    }
    for p in parts {
        out.extend_from_slice(p);
    }
}

/// Takes one whole frame from the front of `buf` (bytes read so far), unmasking it: `None`
/// until it is all there.
pub fn take_frame(buf: &mut Vec<u8>) -> io::Result<Option<(u8, Vec<u8>)>> {
    if buf.len() < 2 {
        return Ok(None);
    }
    let (opcode, masked, len7) = (buf[0] & 0x0f, buf[1] & 0x80 != 0, (buf[1] & 0x7f) as u64);
    let (len, mut at) = match len7 {
        126 if buf.len() >= 4 => (u16::from_be_bytes([buf[2], buf[3]]) as u64, 4),
        127 if buf.len() >= 10 => (
            u64::from_be_bytes(buf[2..10].try_into().unwrap_or([0; 8])),
            10,
        ),
        126 | 127 => return Ok(None),
        n => (n, 2),
    };
    if len > MAX_CLIENT_FRAME {
        return Err(io::Error::other(format!("a client frame of {len} bytes")));
    }
    let mask = if masked {
        if buf.len() < at + 4 {
            return Ok(None);
        }
        at += 4;
        buf[at - 4..at].to_vec()
    } else {
        vec![0; 4]
    };
    let end = at + len as usize;
    if buf.len() < end {
        return Ok(None);
    }
    let payload = buf[at..end]
        .iter()
        .enumerate()
        .map(|(i, b)| b ^ mask[i % 4])
        .collect();
    buf.drain(..end);
    Ok(Some((opcode, payload)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_accept_key_is_rfc_6455s_example() {
        assert_eq!(
            accept_key("dGhlIHNhbXBsZSBub25jZQ=="),
            "s3pPLMBiTxaQ9kYGzzhZRbK+xOo="
        );
        assert_eq!(base64(b"ab"), "YWI=");
        assert_eq!(base64(b"abc"), "YWJj");
    }

    #[test]
    fn frames_round_trip_at_every_length_form_and_partial_input_waits() {
        for len in [0usize, 125, 126, 70_000] {
            let payload = vec![7u8; len];
            let mut out = Vec::new();
            frame(&mut out, BINARY, &[&payload]);
            let mut part = out[..out.len() - 1].to_vec();
            assert!(take_frame(&mut part).unwrap().is_none());
            let (op, p) = take_frame(&mut out).unwrap().unwrap();
            assert_eq!((op, p.len()), (BINARY, len));
            assert!(out.is_empty());
        }
        // A masked client frame.
        let mut f = vec![0x81, 0x80 | 2, 1, 2, 3, 4, b'h' ^ 1, b'i' ^ 2];
        assert_eq!(take_frame(&mut f).unwrap().unwrap(), (TEXT, b"hi".to_vec()));
    }
}
