//! Where and what the service subscribes to (`serve --mqtt-*`): parsed and checked at start-up,
//! held in the service's [`Settings`](crate::configuration::Settings).

use super::topic::TopicFilter;

/// Where and what to subscribe to.
#[derive(Debug, Clone)]
pub struct MqttSettings {
    pub host: String,
    pub port: u16,
    pub username: Option<String>,
    pub password: Option<String>,
    pub filter: TopicFilter,
    /// The persistent session's client id (one per replica).
    pub client_id: String,
    /// Where refused payloads' problems go.
    pub error_topic: String,
}

impl MqttSettings {
    /// From `--mqtt-url mqtt://[user[:password]@]host[:port]` (port 1883 by default),
    /// `--mqtt-topic`, `--mqtt-client-id` and `--mqtt-error-topic`; errors name the flag.
    pub fn parse(
        url: &str,
        topic: &str,
        client_id: &str,
        error_topic: &str,
    ) -> Result<MqttSettings, String> {
        let u = url::Url::parse(url).map_err(|e| format!("--mqtt-url `{url}`: {e}"))?;
        if !matches!(u.scheme(), "mqtt" | "tcp") {
            return Err(format!(
                "--mqtt-url `{url}`: only plain TCP is supported (`mqtt://host:1883`); for \
                 TLS, run the broker's TLS listener behind a local bridge"
            ));
        }
        let host = u
            .host_str()
            .filter(|h| !h.is_empty())
            .ok_or_else(|| format!("--mqtt-url `{url}` names no host"))?;
        let filter = TopicFilter::parse(topic)?;
        if filter.matches(error_topic) || error_topic.contains(['+', '#']) || error_topic.is_empty()
        {
            return Err(format!(
                "--mqtt-error-topic `{error_topic}` must be a topic name outside --mqtt-topic \
                 `{topic}` (the service would read its own error messages)"
            ));
        }
        if client_id.is_empty() || client_id.len() > 64 {
            return Err("--mqtt-client-id is 1 to 64 characters".into());
        }
        Ok(MqttSettings {
            host: host.trim_matches(['[', ']']).to_string(),
            port: u.port().unwrap_or(1883),
            username: (!u.username().is_empty()).then(|| u.username().to_string()),
            password: u.password().map(str::to_string),
            filter,
            client_id: client_id.to_string(),
            error_topic: error_topic.to_string(),
        })
    }
}
