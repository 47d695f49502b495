//! The subscription's topic filter and the machine id a message's topic carries.
//!
//! A filter has exactly one `+` level, which is where the machine id sits in each topic
//! (`plant/+/vibration` → `plant/press-7/vibration` is machine `press-7`); a last level `#`
//! is allowed (`plant/+/#`). A shared subscription, `$share/{group}/{filter}`, spreads the
//! messages over several replicas; its prefix is not part of the topics.

/// A validated filter.
#[derive(Debug, Clone)]
pub struct TopicFilter {
    /// As subscribed (with a `$share/{group}/` prefix when given).
    pub subscription: String,
    /// The levels topics are matched against (without the prefix).
    levels: Vec<String>,
    /// Index of the `+` level.
    machine_level: usize,
}

impl TopicFilter {
    /// Parse `filter`; the error says what to change (it names `--mqtt-topic`).
    pub fn parse(filter: &str) -> Result<TopicFilter, String> {
        let body = match filter.strip_prefix("$share/") {
            Some(rest) => match rest.split_once('/') {
                Some((group, f)) if !group.is_empty() && !f.is_empty() => f,
                _ => {
                    return Err(format!(
                        "--mqtt-topic `{filter}`: a shared subscription is `$share/GROUP/FILTER`"
                    ));
                }
            },
            None => filter,
        };
        let levels: Vec<String> = body.split('/').map(str::to_string).collect();
        let pluses: Vec<usize> = (0..levels.len()).filter(|&i| levels[i] == "+").collect();
        if pluses.len() != 1 {
            return Err(format!(
                "--mqtt-topic `{filter}` must have exactly one `+` level, where the machine id \
                 is (such as `plant/+/vibration`); it has {}",
                pluses.len()
            ));
        }
        for (i, l) in levels.iter().enumerate() {
            let last = i + 1 == levels.len();
            if (l.contains('#') && !(l == "#" && last)) || (l.contains('+') && l != "+") {
                return Err(format!(
                    "--mqtt-topic `{filter}`: `+` must be a whole level and `#` only the whole \
                     last level"
                ));
            }
        }
        Ok(TopicFilter {
            subscription: filter.to_string(),
            levels,
            machine_level: pluses[0],
        })
    }

    /// Whether `topic` matches the filter (MQTT's rules for `+` and a last `#`).
    pub fn matches(&self, topic: &str) -> bool {
        let t: Vec<&str> = topic.split('/').collect();
        for (i, l) in self.levels.iter().enumerate() {
            match l.as_str() {
                "#" => return true,
                "+" if i < t.len() => {}
                _ if i < t.len() && t[i] == l => {}
                _ => return false,
            }
        }
        t.len() == self.levels.len()
    }

    /// The machine id in `topic` (the level at the filter's `+`), if the topic matches.
    pub fn machine_id<'a>(&self, topic: &'a str) -> Option<&'a str> {
        if !self.matches(topic) {
            return None;
        }
        topic.split('/').nth(self.machine_level)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_plus_level_is_the_machine() {
        let f = TopicFilter::parse("plant/+/vibration").unwrap();
        assert_eq!(f.machine_id("plant/press-7/vibration"), Some("press-7"));
        assert_eq!(f.machine_id("plant/press-7/vibration/errors"), None);
        assert_eq!(f.machine_id("other/press-7/vibration"), None);
        let f = TopicFilter::parse("$share/gw/plant/+/#").unwrap();
        assert_eq!(f.machine_id("plant/m1/vibration/x"), Some("m1"));
        assert!(f.matches("plant/m1"));
    }

    #[test]
    fn filters_without_one_plus_are_refused() {
        for bad in [
            "plant/vibration",
            "plant/+/+/v",
            "plant/+/#/x",
            "plant/a+/+",
            "$share//+",
        ] {
            let e = TopicFilter::parse(bad).unwrap_err();
            assert!(e.contains("--mqtt-topic"), "{bad}: {e}");
        }
    }
}
