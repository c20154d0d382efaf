//! A client of Foxglove's WebSocket protocol (`foxglove.sdk.v1` or `foxglove.websocket.v1`,
//! <https://github.com/foxglove/ws-protocol> `docs/spec.md`; the subset a viewer uses:
//! advertisements, subscriptions, message data, client publishing, parameters), for tests of
//! the live view.

use std::collections::HashMap;
use std::net::TcpStream;
use std::time::{Duration, Instant};

use serde_json::{Value, json};
use tungstenite::client::IntoClientRequest;
use tungstenite::stream::MaybeTlsStream;
use tungstenite::{Message, WebSocket};

/// One message-data frame: subscription id, log time (Unix ns), payload.
pub struct Data {
    /// The client's subscription id.
    pub subscription: u32,
    /// The message's log time, ns since the Unix epoch.
    pub log_ns: u64,
    /// The encoded message.
    pub payload: Vec<u8>,
}

/// A connected client and the channels advertised to it, by topic.
pub struct Client {
    socket: WebSocket<MaybeTlsStream<TcpStream>>,
    /// Advertised channels (`id`, `topic`, `encoding`, `schemaName`, ...), by topic.
    pub channels: HashMap<String, Value>,
    /// The subprotocol the server selected.
    pub subprotocol: String,
    /// The server's other JSON messages (`serverInfo`, `status`, `parameterValues`, ...), in
    /// order.
    pub texts: Vec<Value>,
}

/// The SDK's name of the protocol.
pub const SDK_V1: &str = "foxglove.sdk.v1";
/// The ws-protocol specification's name of the protocol.
pub const WEBSOCKET_V1: &str = "foxglove.websocket.v1";

impl Client {
    /// Connects to `url` (`ws://HOST:PORT`), retrying until `timeout` (a server still starting
    /// refuses connections).
    pub fn connect(url: &str, timeout: Duration) -> Self {
        Self::connect_as(url, SDK_V1, timeout)
    }

    /// [`Client::connect`] offering only `subprotocol`; panics unless the server selects it.
    pub fn connect_as(url: &str, subprotocol: &str, timeout: Duration) -> Self {
        let start = Instant::now();
        let (socket, selected) = loop {
            let mut request = url.into_client_request().expect("a ws:// URL");
            request
                .headers_mut()
                .insert("Sec-WebSocket-Protocol", subprotocol.parse().unwrap());
            match tungstenite::connect(request) {
                Ok((socket, response)) => {
                    let selected = response.headers().get("Sec-WebSocket-Protocol").cloned();
                    break (socket, selected);
                }
                Err(e) => {
                    assert!(start.elapsed() < timeout, "cannot connect to {url}: {e}");
                    std::thread::sleep(Duration::from_millis(100));
                }
            }
        };
        if let MaybeTlsStream::Plain(tcp) = socket.get_ref() {
            tcp.set_read_timeout(Some(Duration::from_millis(20)))
                .unwrap();
        }
        let selected = selected.map(|v| v.to_str().unwrap().to_string());
        assert_eq!(
            selected.as_deref(),
            Some(subprotocol),
            "selected subprotocol"
        );
        Self {
            socket,
            channels: HashMap::new(),
            subprotocol: subprotocol.to_string(),
            texts: Vec::new(),
        }
    }

    /// Sends one JSON message.
    pub fn send(&mut self, message: &Value) {
        self.socket
            .send(Message::Text(message.to_string().into()))
            .unwrap();
    }

    /// Advertises a client channel `id` on `topic` with message encoding `encoding` and schema
    /// name `schema_name` (the protocol's `advertise`, client side).
    pub fn advertise(&mut self, id: u32, topic: &str, encoding: &str, schema_name: &str) {
        let channel =
            json!({"id": id, "topic": topic, "encoding": encoding, "schemaName": schema_name});
        self.send(&json!({"op": "advertise", "channels": [channel]}));
    }

    /// Publishes `payload` on client channel `id` (opcode 1, channel id, payload).
    pub fn publish(&mut self, id: u32, payload: &[u8]) {
        let mut frame = vec![1u8];
        frame.extend_from_slice(&id.to_le_bytes());
        frame.extend_from_slice(payload);
        self.socket.send(Message::Binary(frame.into())).unwrap();
    }

    /// Reads until a JSON message with `op` arrives (panics after `timeout`); returns it.
    pub fn wait_for_op(&mut self, op: &str, timeout: Duration) -> Value {
        let start = Instant::now();
        loop {
            if let Some(i) = self.texts.iter().position(|m| m["op"] == op) {
                return self.texts.remove(i);
            }
            assert!(start.elapsed() < timeout, "no {op:?}; got {:?}", self.texts);
            let _ = self.read();
        }
    }

    /// Reads advertisements until `topics` are all advertised (panics after `timeout`).
    pub fn wait_for_channels(&mut self, topics: &[&str], timeout: Duration) {
        let start = Instant::now();
        while !topics.iter().all(|t| self.channels.contains_key(*t)) {
            assert!(
                start.elapsed() < timeout,
                "advertised so far: {:?}",
                self.channels.keys()
            );
            let _ = self.read();
        }
    }

    /// The schema name of the channel advertised for `topic`.
    pub fn schema(&self, topic: &str) -> &str {
        self.channels[topic]["schemaName"].as_str().unwrap()
    }

    /// Subscribes to `topics`, subscription ids 1, 2, ... in order.
    pub fn subscribe(&mut self, topics: &[&str]) {
        let subscriptions: Vec<Value> = topics
            .iter()
            .zip(1..)
            .map(|(t, id)| json!({"id": id, "channelId": self.channels[*t]["id"]}))
            .collect();
        self.send(&json!({"op": "subscribe", "subscriptions": subscriptions}));
    }

    /// The next message-data frame, if one arrives within the read timeout (20 ms);
    /// advertisements and other JSON messages read meanwhile are kept.
    pub fn read(&mut self) -> Option<Data> {
        match self.socket.read() {
            Ok(Message::Text(text)) => {
                let msg: Value = serde_json::from_str(&text).unwrap();
                if msg["op"] == "advertise" {
                    for c in msg["channels"].as_array().unwrap() {
                        let topic = c["topic"].as_str().unwrap().to_string();
                        self.channels.insert(topic, c.clone());
                    }
                } else {
                    self.texts.push(msg);
                }
                None
            }
            // Opcode 1, message data: subscription id (u32), log time (u64), payload.
            Ok(Message::Binary(data)) if data.first() == Some(&1) => Some(Data {
                subscription: u32::from_le_bytes(data[1..5].try_into().unwrap()),
                log_ns: u64::from_le_bytes(data[5..13].try_into().unwrap()),
                payload: data[13..].to_vec(),
            }),
            Ok(_) => None,
            Err(tungstenite::Error::Io(e))
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                None
            }
            Err(e) => panic!("websocket: {e}"),
        }
    }
}
