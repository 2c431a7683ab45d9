//! One bus per prefix: who is already on the services of a service-name prefix, and whether a
//! prefix can name services at all — checked by `sextant run` before it starts anything.
//!
//! Two runs with the same prefix would share every service: each fusion would fuse both runs'
//! drivers, each status line would show the other's counters, and neither would notice. A run
//! therefore refuses to start while a live node (of any process) is attached to a service
//! `<prefix>/…`, and names those processes. Dead nodes (a crashed run) do not count: their
//! shared memory is removed first.

use iceoryx2::node::NodeView;
use iceoryx2::prelude::*;
use msgs::Channel;

/// A live process attached to a service of the prefix.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub struct LiveNode {
    /// Process id.
    pub pid: i32,
    /// iceoryx2 node name (`sextant-fusion`, `sim-imu`, …).
    pub name: String,
    /// Executable name as iceoryx2 recorded it.
    pub executable: String,
}

impl std::fmt::Display for LiveNode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} (pid {}, {})", self.name, self.pid, self.executable)
    }
}

/// The services could not be listed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("cannot list the iceoryx2 services: {0:?}")]
pub struct BusListError(pub iceoryx2::service::ServiceListError);

/// A service-name prefix that cannot name every service of a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum PrefixError {
    /// Empty.
    #[error("the service prefix is empty")]
    Empty,
    /// Longer than the services' names allow.
    #[error(
        "the service prefix is {len} characters long; at most {max} fit in an iceoryx2 service name (`<prefix>/star_tracker` ≤ 255)"
    )]
    TooLong {
        /// Its length, bytes.
        len: usize,
        /// The longest accepted, bytes.
        max: usize,
    },
    /// Holds a character outside `A-Z a-z 0-9 _ - . /`.
    #[error(
        "the service prefix holds {ch:?} at position {at}; use letters, digits and _ - . / only"
    )]
    BadChar {
        /// The character.
        ch: char,
        /// Its position, characters from 0.
        at: usize,
    },
}

/// Longest accepted prefix, bytes: `<prefix>/<channel>` must fit iceoryx2's 255-byte service
/// name for the longest channel name.
pub fn max_prefix_len() -> usize {
    let longest = Channel::ALL
        .iter()
        .map(|c| c.name().len())
        .max()
        .unwrap_or(0);
    ServiceName::max_len() - 1 - longest
}

/// Check that `prefix` names valid services for every channel: not empty, at most
/// [`max_prefix_len`] bytes, only `A-Z a-z 0-9 _ - . /` (so never iceoryx2's reserved `iox2://`).
pub fn validate_prefix(prefix: &str) -> Result<(), PrefixError> {
    if prefix.is_empty() {
        return Err(PrefixError::Empty);
    }
    if let Some((at, ch)) = prefix
        .chars()
        .enumerate()
        .find(|(_, c)| !(c.is_ascii_alphanumeric() || "_-./".contains(*c)))
    {
        return Err(PrefixError::BadChar { ch, at });
    }
    let max = max_prefix_len();
    if prefix.len() > max {
        return Err(PrefixError::TooLong {
            len: prefix.len(),
            max,
        });
    }
    Ok(())
}

/// Live processes attached to a service `<prefix>/…` (pub-sub or event), without duplicates,
/// excluding the calling process. Call after removing dead nodes
/// (`msgs::ipc::cleanup_dead_nodes`): a dead node holds no process.
pub fn live_nodes_on(prefix: &str) -> Result<Vec<LiveNode>, BusListError> {
    let me = std::process::id() as i32;
    let head = format!("{prefix}/");
    let mut found: Vec<LiveNode> = Vec::new();
    msgs::ipc::IpcService::list(Config::global_config(), |details| {
        let name = details.static_details.name().as_str();
        let ours = name
            .strip_prefix(&head)
            .is_some_and(|rest| Channel::from_name(rest).is_some());
        if !ours {
            return CallbackProgression::Continue;
        }
        for node in details.dynamic_details.iter().flat_map(|d| d.nodes.iter()) {
            let NodeState::Alive(view) = node else {
                continue;
            };
            let Ok(pid) = view.id().pid::<msgs::ipc::IpcService>() else {
                continue;
            };
            let pid = pid.value();
            if pid == me {
                continue;
            }
            let (name, executable) = view.details().as_ref().map_or_else(
                || ("?".to_string(), "?".to_string()),
                |d| {
                    (
                        d.name().as_str().to_string(),
                        String::from_utf8_lossy(d.executable().as_bytes()).to_string(),
                    )
                },
            );
            let n = LiveNode {
                pid,
                name,
                executable,
            };
            if !found.contains(&n) {
                found.push(n);
            }
        }
        CallbackProgression::Continue
    })
    .map_err(BusListError)?;
    found.sort();
    Ok(found)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prefixes_are_validated() {
        assert_eq!(validate_prefix("sextant"), Ok(()));
        assert_eq!(validate_prefix("sextant_disk-1.a/b"), Ok(()));
        assert_eq!(validate_prefix(""), Err(PrefixError::Empty));
        assert_eq!(
            validate_prefix("a b"),
            Err(PrefixError::BadChar { ch: ' ', at: 1 })
        );
        assert_eq!(
            validate_prefix("iox2://x"),
            Err(PrefixError::BadChar { ch: ':', at: 4 })
        );
        let max = max_prefix_len();
        assert_eq!(max, 255 - 1 - "star_tracker".len());
        assert_eq!(validate_prefix(&"p".repeat(max)), Ok(()));
        assert_eq!(
            validate_prefix(&"p".repeat(300)),
            Err(PrefixError::TooLong { len: 300, max })
        );
    }

    #[test]
    fn a_live_node_on_the_prefix_is_found_and_another_prefix_is_free() {
        let prefix = format!("sextant_buscheck_{}", std::process::id());
        assert_eq!(live_nodes_on(&prefix).unwrap(), []);
        // A child process joins the bus: it is found by its pid.
        let exe = std::env::current_exe().unwrap();
        let mut child = std::process::Command::new(exe)
            .args([
                "--exact",
                "bus_check::tests::bus_member",
                "--ignored",
                "--nocapture",
            ])
            .env("SEXTANT_BUS_MEMBER_PREFIX", &prefix)
            .stdout(std::process::Stdio::null())
            .spawn()
            .unwrap();
        let t0 = std::time::Instant::now();
        let nodes = loop {
            let n = live_nodes_on(&prefix).unwrap();
            if !n.is_empty() || t0.elapsed() > std::time::Duration::from_secs(20) {
                break n;
            }
            std::thread::sleep(std::time::Duration::from_millis(50));
        };
        let _ = child.kill();
        let _ = child.wait();
        assert_eq!(nodes.len(), 1, "{nodes:?}");
        assert_eq!(nodes[0].pid, child.id() as i32);
        assert_eq!(nodes[0].name, "bus-member");
        assert_eq!(live_nodes_on(&format!("{prefix}x")).unwrap(), []);
        let _ = msgs::ipc::cleanup_dead_nodes();
    }

    /// Helper process of the test above: holds a subscriber on the prefix for 30 s.
    #[test]
    #[ignore = "started by a_live_node_on_the_prefix_is_found_and_another_prefix_is_free"]
    fn bus_member() {
        let Ok(prefix) = std::env::var("SEXTANT_BUS_MEMBER_PREFIX") else {
            return;
        };
        let bus = msgs::ipc::Bus::new(&prefix, "bus-member").unwrap();
        let _sub = bus.subscriber::<msgs::Status>().unwrap();
        std::thread::sleep(std::time::Duration::from_secs(30));
    }
}
