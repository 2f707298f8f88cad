//! Commands over MQTT: a request published on `surfscan/<station>/commands/<client-id>`
//! (the same JSON object the control socket reads, e.g. `{"class":"pause"}` or
//! `{"class":"queue-add","recipe":"shaft"}`) carried out through the socket's own
//! [`dispatch`], so it is accepted or refused as there, in the same words; the answer (the
//! socket's message, with `client_id`, `time` and the request's `id` when it gave one) goes to
//! `surfscan/<station>/replies/<client-id>`.
//!
//! MQTT 3.1.1 does not tell a receiver who published a message, so the sender is the last
//! level of the command's topic, and it is to be trusted only where the broker lets each
//! client write its own command topic alone (Mosquitto: `pattern write
//! surfscan/+/commands/%c`, docs/integration.md). The client id is recorded with the command
//! as its peer ([`Peer::mqtt_client`]) in the scan's journal or the queue, and every command,
//! accepted or refused, is logged with it.
//!
//! Refused without being carried out: every command while `[mqtt] commands = false`; a
//! command handed over as a retained message, kept from before the station subscribed (it
//! would be carried out again at every reconnection); a repeated `id`
//! of the same client (a QoS 1 message the broker delivered twice).
//!
//! Layer 4 (process edge): depends on the control socket's request parser and dispatch, and
//! the scan's command types; the MQTT link ([`super::mqtt`]) feeds it and publishes its
//! replies.

use crate::control::dispatch::dispatch;
use crate::control::protocol::{ControlChannels, Message};
use crate::control::server::parse_request;
use crate::scan::command::Peer;
use std::collections::{HashMap, VecDeque};
use std::time::Duration;

/// How many request ids of each client are remembered to drop a repeated delivery.
const REMEMBERED_IDS: usize = 64;

/// A command as it arrived from the broker.
#[derive(Debug, Clone)]
pub struct Incoming {
    /// Its topic.
    pub topic: String,
    /// Its payload.
    pub payload: Vec<u8>,
    /// Whether the broker delivered it as a retained message.
    pub retained: bool,
}

/// The command topic filter of `station`'s root (`surfscan/<station>`).
pub fn filter(root: &str) -> String {
    format!("{root}/commands/+")
}

/// The sender of a message on `topic`: its last level below `<root>/commands/`.
pub fn sender<'a>(root: &str, topic: &'a str) -> Option<&'a str> {
    topic
        .strip_prefix(root)?
        .strip_prefix("/commands/")
        .filter(|c| !c.is_empty() && !c.contains('/'))
}

/// Carries out commands and words their replies; remembers each client's last request ids.
pub struct Commands {
    root: String,
    enabled: bool,
    channels: ControlChannels,
    reply_timeout: Duration,
    seen: HashMap<String, VecDeque<String>>,
}

fn refusal(message: String) -> Message {
    Message::Error { message }
}

impl Commands {
    /// Commands for the station at `root`, carried out only when `enabled`.
    pub fn new(root: String, enabled: bool, channels: ControlChannels) -> Commands {
        Commands {
            root,
            enabled,
            channels,
            reply_timeout: crate::control::server::ServerOptions::default().reply_timeout,
            seen: HashMap::new(),
        }
    }

    /// The reply's topic and payload for `m` (none for a topic that is not a command's, or
    /// an empty payload: the clearing of a retained message).
    pub async fn answer(&mut self, m: Incoming) -> Option<(String, String)> {
        let client = sender(&self.root, &m.topic)?.to_owned();
        if m.payload.is_empty() {
            return None;
        }
        let (request_id, reply) = self.carry_out(&client, &m).await;
        let class = match &reply {
            Message::Ack { detail, .. } => format!("accepted: {detail}"),
            Message::Error { message } | Message::Refused { message, .. } => {
                format!("refused: {message}")
            }
            _ => "answered".to_owned(),
        };
        let words = String::from_utf8_lossy(&m.payload);
        if class.starts_with("refused") {
            tracing::warn!("mqtt: command {words} from MQTT client {client} {class}");
        } else {
            tracing::info!("mqtt: command {words} from MQTT client {client} {class}");
        }
        let mut v = serde_json::to_value(&reply).unwrap_or_default();
        if let Some(o) = v.as_object_mut() {
            o.insert("client_id".into(), client.clone().into());
            o.insert(
                "time".into(),
                chrono::Utc::now()
                    .to_rfc3339_opts(chrono::SecondsFormat::Millis, true)
                    .into(),
            );
            if let Some(id) = request_id {
                o.insert("id".into(), id);
            }
        }
        Some((format!("{}/replies/{client}", self.root), v.to_string()))
    }

    /// The request's `id` (when it gave one) and the answer to it.
    async fn carry_out(
        &mut self,
        client: &str,
        m: &Incoming,
    ) -> (Option<serde_json::Value>, Message) {
        let mut value: serde_json::Value = match serde_json::from_slice(&m.payload) {
            Ok(v) => v,
            Err(e) => {
                return (
                    None,
                    refusal(format!(
                        "the command is not JSON ({e}); publish one JSON object such as {{\"class\":\"pause\"}}, and nothing is carried out"
                    )),
                )
            }
        };
        let id = value.as_object_mut().and_then(|o| o.remove("id"));
        if m.retained {
            return (id, refusal("a retained command is not carried out (the broker would hand it over again at every reconnection): publish it without the retain flag, and clear the retained one with an empty message".into()));
        }
        if let Some(key) = id.as_ref().map(|i| i.to_string()) {
            let ids = self.seen.entry(client.to_owned()).or_default();
            if ids.contains(&key) {
                return (id, refusal(format!("request id {key} of {client} was already carried out (the broker delivered it twice); it is not carried out again: give each request a new id")));
            }
            ids.push_back(key);
            if ids.len() > REMEMBERED_IDS {
                ids.pop_front();
            }
        }
        let request = match parse_request(&value.to_string()) {
            Ok(r) => r,
            Err(message) => return (id, message),
        };
        let enabled = self.enabled;
        let who = |name: &'static str| -> Result<Peer, Message> {
            if enabled {
                Ok(Peer::mqtt_client(client))
            } else {
                Err(refusal(format!(
                    "{name} refused: this station takes no commands over MQTT ([mqtt] commands = false); give it at the station (`surfscan {name}` or its page), or ask its administrator to set [mqtt] commands = true with the broker ACL in docs/integration.md"
                )))
            }
        };
        let reply = dispatch(request, &self.channels, who, self.reply_timeout).await;
        (id, reply)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_sender_is_the_one_level_below_commands() {
        let root = "surfscan/st-1";
        assert_eq!(sender(root, "surfscan/st-1/commands/mes-7"), Some("mes-7"));
        assert_eq!(sender(root, "surfscan/st-1/commands/"), None);
        assert_eq!(sender(root, "surfscan/st-1/commands/a/b"), None);
        assert_eq!(sender(root, "surfscan/st-10/commands/a"), None);
        assert_eq!(sender(root, "surfscan/st-1/status"), None);
    }
}
