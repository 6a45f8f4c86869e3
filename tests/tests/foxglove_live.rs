//! The live view through the real daemon and plant: a WebSocket client, written out here as
//! Foxglove speaks it, connects to `[daemon] foxglove`, reads the advertised channels,
//! subscribes, and decodes live joint states, the robot's description and the scene; and, when
//! `CHAOSD_FOXGLOVE_CHECK` names scripts/foxglove-check, Foxglove's own client and decoders do.

use daemon::view::cdr::decode_joint_state;
use daemon::view::Topic;
use std::io::{Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};
use tests::foxglove_check::{self, bits, ns};
use tests::live::*;
use tests::*;

/// A free port on loopback (bound, then let go: the daemon binds it next).
fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// The client's side of the WebSocket: a masked text frame.
fn send_text(s: &mut TcpStream, text: &str) {
    send_frame(s, 0x1, text.as_bytes());
}

/// A masked frame of `opcode`.
fn send_frame(s: &mut TcpStream, opcode: u8, payload: &[u8]) {
    let mask = [0x11u8, 0x22, 0x33, 0x44];
    let mut f = vec![0x80 | opcode];
    match payload.len() {
        n @ 0..=125 => f.push(0x80 | n as u8),
        n => {
            f.push(0x80 | 126);
            f.extend_from_slice(&(n as u16).to_be_bytes());
        }
    }
    f.extend_from_slice(&mask);
    f.extend(payload.iter().enumerate().map(|(i, b)| b ^ mask[i % 4]));
    s.write_all(&f).unwrap();
}

/// Reads one whole frame: (opcode, payload).
fn read_frame(s: &mut TcpStream) -> (u8, Vec<u8>) {
    let mut h = [0u8; 2];
    s.read_exact(&mut h).unwrap();
    let len = match h[1] & 0x7f {
        126 => {
            let mut b = [0u8; 2];
            s.read_exact(&mut b).unwrap();
            u16::from_be_bytes(b) as usize
        }
        127 => {
            let mut b = [0u8; 8];
            s.read_exact(&mut b).unwrap();
            u64::from_be_bytes(b) as usize
        }
        n => n as usize,
    };
    let mut p = vec![0u8; len];
    s.read_exact(&mut p).unwrap();
    (h[0] & 0x0f, p)
}

#[test]
fn a_viewer_gets_the_channels_and_decodes_live_joint_states_and_the_urdf() {
    let _g = serial();
    let port = free_port();
    let sys = start_with_daemon("foxglove", "", &format!("foxglove = \"127.0.0.1:{port}\""));
    let mut s = TcpStream::connect(("127.0.0.1", port)).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    write!(
        s,
        "GET / HTTP/1.1\r\nHost: localhost\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
         Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\
         Sec-WebSocket-Protocol: foxglove.websocket.v1\r\n\r\n"
    )
    .unwrap();
    let mut head = Vec::new();
    let mut b = [0u8; 1];
    while !head.ends_with(b"\r\n\r\n") {
        s.read_exact(&mut b).unwrap();
        head.push(b[0]);
    }
    let head = String::from_utf8(head).unwrap();
    assert!(head.starts_with("HTTP/1.1 101"), "{head}");
    assert!(head.contains("s3pPLMBiTxaQ9kYGzzhZRbK+xOo="), "{head}");
    assert!(
        head.contains("Sec-WebSocket-Protocol: foxglove.websocket.v1"),
        "{head}"
    );
    let (op, info) = read_frame(&mut s);
    let info: serde_json::Value = serde_json::from_slice(&info).unwrap();
    assert_eq!((op, info["op"].as_str()), (1, Some("serverInfo")), "{info}");
    let (_, adv) = read_frame(&mut s);
    let adv: serde_json::Value = serde_json::from_slice(&adv).unwrap();
    assert_eq!(adv["op"], "advertise");
    let channels = adv["channels"].as_array().unwrap();
    let id = |topic: &str| {
        channels
            .iter()
            .find(|c| c["topic"] == topic)
            .unwrap_or_else(|| panic!("{topic} not advertised: {adv}"))["id"]
            .as_u64()
            .unwrap()
    };
    let js = channels
        .iter()
        .find(|c| c["topic"] == "/joint_states")
        .unwrap();
    assert_eq!(js["schemaName"], "sensor_msgs/msg/JointState");
    assert_eq!(
        (js["encoding"].as_str(), js["schemaEncoding"].as_str()),
        (Some("cdr"), Some("ros2msg"))
    );
    for t in [
        "/tf",
        "/chaosd/scene",
        "/chaosd/residual",
        "/chaosd/timing",
        "/chaosd/events",
    ] {
        id(t);
    }
    let subs = serde_json::json!({"op": "subscribe", "subscriptions": [
        {"id": 7, "channelId": id("/joint_states")},
        {"id": 8, "channelId": id("/robot_description")},
        {"id": 9, "channelId": id("/chaosd/scene")},
    ]});
    send_text(&mut s, &subs.to_string());
    let (mut states, mut urdf, mut scene) = (0, false, false);
    let mut last_stamp = 0u64;
    let until = Instant::now() + Duration::from_secs(10);
    while (states < 200 || !urdf || !scene) && Instant::now() < until {
        let (op, p) = read_frame(&mut s);
        assert_eq!((op, p[0]), (2, 1), "a binary messageData frame");
        let sub = u32::from_le_bytes(p[1..5].try_into().unwrap());
        let stamp = u64::from_le_bytes(p[5..13].try_into().unwrap());
        let data = &p[13..];
        match sub {
            7 => {
                let j = decode_joint_state(data).unwrap();
                assert_eq!(j.name, ["joint1", "joint2", "joint3"]);
                assert!(j.position.iter().all(|q| q.is_finite()));
                assert_eq!(j.stamp_ns, stamp);
                assert!(stamp >= last_stamp, "time runs forwards");
                last_stamp = stamp;
                states += 1;
            }
            8 => urdf = String::from_utf8_lossy(&data[8..]).contains("<robot"),
            9 => scene = serde_json::from_slice::<serde_json::Value>(data).is_ok(),
            other => panic!("a message for subscription {other}, never asked for"),
        }
    }
    assert!(
        states >= 200 && urdf && scene,
        "{states} states, urdf {urdf}, scene {scene}"
    );
    // Unsubscribed, nothing more comes for it; the daemon runs on.
    send_text(&mut s, r#"{"op":"unsubscribe","subscriptionIds":[7,8,9]}"#);
    // A Close is answered with a Close carrying the same status (RFC 6455 §5.5.1), not a reset.
    send_frame(&mut s, 0x8, &1000u16.to_be_bytes());
    let until = Instant::now() + Duration::from_secs(5);
    let close = loop {
        assert!(
            Instant::now() < until,
            "no Close answered the viewer's Close"
        );
        let (op, p) = read_frame(&mut s);
        if op == 0x8 {
            break p;
        }
    };
    assert_eq!(close, 1000u16.to_be_bytes(), "{close:?}");
    drop(s);
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(status(&sys.ns)["mode"], "Run");
}

/// Clients that connect and say nothing (each handshake waits up to 2 s for its request) do not
/// hold up a viewer that connects after them: with the handshakes done one after another, the
/// three silent ones would keep it waiting 6 s.
#[test]
fn silent_connections_do_not_keep_a_viewer_waiting() {
    let _g = serial();
    let port = free_port();
    let sys = start_with_daemon(
        "foxglove-silent",
        "",
        &format!("foxglove = \"127.0.0.1:{port}\""),
    );
    let addr = format!("127.0.0.1:{port}");
    let silent: Vec<TcpStream> = (0..3).map(|_| TcpStream::connect(&addr).unwrap()).collect();
    std::thread::sleep(Duration::from_millis(100));
    let started = Instant::now();
    let (mut s, topics) = daemon::foxglove::client::subscribe_all(&addr, Duration::from_secs(2))
        .expect("the viewer's handshake");
    let (op, _) = read_frame(&mut s);
    let waited = started.elapsed();
    assert!(topics.iter().any(|t| t == "/joint_states"), "{topics:?}");
    assert_eq!(op, 2, "a binary messageData frame");
    assert!(
        waited < Duration::from_secs(3),
        "the viewer waited {waited:?} behind silent connections"
    );
    drop(silent);
    assert_eq!(status(&sys.ns)["mode"], "Run");
}

/// Foxglove's own WebSocket client (@foxglove/ws-protocol) subscribes to every channel for a
/// few seconds; every message decodes with the decoder the app picks and is valid against its
/// schemas, official foxglove.* ones included (scripts/foxglove-check).
#[test]
fn foxglove_s_own_client_decodes_and_validates_every_live_channel() {
    if foxglove_check::configured().is_none() {
        return;
    }
    let _g = serial();
    let port = free_port();
    let sys = start_with_daemon(
        "foxglove-check",
        "",
        &format!("foxglove = \"127.0.0.1:{port}\""),
    );
    let url = format!("ws://127.0.0.1:{port}");
    let limit = Duration::from_secs(60);
    let seen = foxglove_check::run(&["live", &url, "3"], sys.dir.path(), limit).unwrap();
    assert_eq!(seen["subprotocol"], "foxglove.websocket.v1", "{seen}");
    assert_eq!(seen["server"]["name"], "chaosd", "{seen}");
    // Every channel chaosd serves is advertised with its schema and encodings, and streams
    // (the events only on change).
    let topics = seen["topics"].as_object().unwrap();
    let offered: Vec<Topic> = Topic::ALL
        .into_iter()
        .filter(|t| *t != Topic::Replay)
        .collect();
    assert_eq!(topics.len(), offered.len(), "{seen}");
    for t in offered {
        let got = &topics[t.name()];
        let (schema, encoding, _) = t.schema();
        assert_eq!(got["schema"], schema, "{}: {got}", t.name());
        assert_eq!(got["schema_encoding"], encoding, "{}: {got}", t.name());
        assert_eq!(got["message_encoding"], t.encoding(), "{}: {got}", t.name());
        if t != Topic::Events {
            assert!(got["count"].as_u64() > Some(0), "{}: {got}", t.name());
        }
    }
    let states = &topics["/joint_states"];
    assert!(states["count"].as_u64() >= Some(200), "{states}");
    let last = &seen["last_joint_state"];
    assert_eq!(
        last["name"],
        serde_json::json!(["joint1", "joint2", "joint3"])
    );
    let q = bits(&last["position"]);
    let finite = q.iter().all(|b| f64::from_bits(*b).is_finite());
    assert!(q.len() == 3 && finite, "{last}");
    assert_eq!(
        ns(&last["stamp_ns"]),
        ns(&states["last_log_time_ns"]),
        "{seen}"
    );
    // The viewer unsubscribed and left; the daemon runs on.
    assert_eq!(status(&sys.ns)["mode"], "Run");
}

#[test]
fn a_bad_address_is_refused_at_start_with_the_key_named() {
    let dir = TempDir::new(&unique_namespace("foxglove-bad"));
    let cfg = write_config(dir.path(), "fgbad", "foxglove = \"localhost\"", "");
    let o = std::process::Command::new(bin("chaosd"))
        .args(["run", "--config", cfg.to_str().unwrap()])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("daemon.foxglove"),
        "{err}"
    );
}

#[test]
fn the_layout_in_deploy_names_only_channels_chaosd_serves() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let text = std::fs::read_to_string(root.join("deploy/foxglove-layout.json")).unwrap();
    let layout: serde_json::Value = serde_json::from_str(&text).unwrap();
    let served: Vec<&str> = daemon::view::Topic::ALL.iter().map(|t| t.name()).collect();
    let mut named = Vec::new();
    for panel in layout["configById"].as_object().unwrap().values() {
        let topics = panel["topics"]
            .as_object()
            .into_iter()
            .flatten()
            .map(|(k, _)| k.clone());
        let paths = panel["paths"].as_array().into_iter().flatten();
        let paths = paths.map(|p| {
            p["value"]
                .as_str()
                .unwrap()
                .split('.')
                .next()
                .unwrap()
                .to_string()
        });
        let layers = panel["layers"].as_object().into_iter().flatten();
        let layers = layers.filter_map(|(_, l)| l["topic"].as_str().map(str::to_string));
        let log = panel["topicToRender"].as_str().map(str::to_string);
        named.extend(topics.chain(paths).chain(layers).chain(log));
    }
    assert!(named.len() >= 8, "{named:?}");
    for t in &named {
        assert!(
            served.contains(&t.as_str()),
            "the layout names {t}, which chaosd does not serve"
        );
    }
    // Every panel in the tree is configured, and every configured panel is in the tree.
    let tree = layout["layout"].to_string();
    for id in layout["configById"].as_object().unwrap().keys() {
        assert!(
            tree.contains(&format!("\"{id}\"")),
            "{id} is not in the layout"
        );
    }
}
