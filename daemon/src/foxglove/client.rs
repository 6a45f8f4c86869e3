//! A viewer's side of the protocol, as small as a measurement needs: connect, subscribe to every
//! channel, count what arrives (`chaosd-bench e2e` attaches one to measure what a viewer costs
//! the loop).

use super::ws;
use std::io::{Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

/// Reads one whole frame from a server (unmasked): (opcode, payload).
pub fn read_frame(s: &mut TcpStream) -> std::io::Result<(u8, Vec<u8>)> {
    let mut h = [0u8; 2];
    s.read_exact(&mut h)?;
    let len = match h[1] & 0x7f {
        126 => {
            let mut b = [0u8; 2];
            s.read_exact(&mut b)?;
            u16::from_be_bytes(b) as usize
        }
        127 => {
            let mut b = [0u8; 8];
            s.read_exact(&mut b)?;
            u64::from_be_bytes(b) as usize
        }
        n => n as usize,
    };
    let mut p = vec![0u8; len];
    s.read_exact(&mut p)?;
    Ok((h[0] & 0x0f, p))
}

/// Connects to `addr` (retrying for up to `wait`), upgrades, reads `serverInfo` and
/// `advertise`, and subscribes to every advertised channel. Returns the socket and the topics.
pub fn subscribe_all(addr: &str, wait: Duration) -> std::io::Result<(TcpStream, Vec<String>)> {
    let until = Instant::now() + wait;
    let mut s = loop {
        match TcpStream::connect(addr) {
            Ok(s) => break s,
            Err(e) if Instant::now() > until => return Err(e),
            Err(_) => std::thread::sleep(Duration::from_millis(50)),
        }
    };
    s.set_read_timeout(Some(Duration::from_secs(5)))?;
    write!(
        s,
        "GET / HTTP/1.1\r\nHost: {addr}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
         Sec-WebSocket-Key: Y2hhb3NkLWJlbmNoLXZpZXc=\r\nSec-WebSocket-Version: 13\r\n\
         Sec-WebSocket-Protocol: {}\r\n\r\n",
        ws::SUBPROTOCOL
    )?;
    let mut head = Vec::new();
    let mut b = [0u8; 1];
    while !head.ends_with(b"\r\n\r\n") {
        s.read_exact(&mut b)?;
        head.push(b[0]);
    }
    if !head.starts_with(b"HTTP/1.1 101") {
        return Err(std::io::Error::other("the server refused the upgrade"));
    }
    let _info = read_frame(&mut s)?;
    let (_, adv) = read_frame(&mut s)?;
    let adv: serde_json::Value =
        serde_json::from_slice(&adv).map_err(|e| std::io::Error::other(e.to_string()))?;
    let channels = adv["channels"].as_array().cloned().unwrap_or_default();
    let subs: Vec<serde_json::Value> = channels
        .iter()
        .enumerate()
        .map(|(i, c)| serde_json::json!({"id": i, "channelId": c["id"]}))
        .collect();
    let text = serde_json::json!({"op": "subscribe", "subscriptions": subs}).to_string();
    // A client's frames are masked (RFC 6455); the mask may be any four bytes.
    let mask = [0x5au8, 0xa5, 0x3c, 0xc3];
    let mut f = vec![0x81];
    match text.len() {
        n @ 0..=125 => f.push(0x80 | n as u8),
        n => {
            f.push(0x80 | 126);
            f.extend_from_slice(&(n as u16).to_be_bytes());
        }
    }
    f.extend_from_slice(&mask);
    f.extend(text.bytes().enumerate().map(|(i, b)| b ^ mask[i % 4]));
    s.write_all(&f)?;
    let topics = channels
        .iter()
        .filter_map(|c| c["topic"].as_str().map(str::to_string))
        .collect();
    Ok((s, topics))
}
