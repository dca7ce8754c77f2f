//! The node's log lines on standard error, in the format of ROS 2's console logger
//! (`[INFO] [1732473600.123456789] [bevt_node]: text`): severity, wall-clock time in seconds
//! since the Unix epoch with nanoseconds, node name. The same messages go to `/rosout` with
//! their own stamp.

use ros2_client::log::LogLevel;
use std::time::{SystemTime, UNIX_EPOCH};

/// The severity as ROS 2 prints it.
pub fn severity(level: LogLevel) -> &'static str {
    match level {
        LogLevel::Fatal => "FATAL",
        LogLevel::Error => "ERROR",
        LogLevel::Warn => "WARN",
        LogLevel::Info => "INFO",
        LogLevel::Debug => "DEBUG",
    }
}

/// Parses a `--log-level` value as `ros2 run … --ros-args --log-level` takes it: a severity
/// (`debug`, `info`, `warn`, `error`, `fatal`, any case) for the node's logger, or
/// `LOGGER:=SEVERITY` for a named logger. Returns the logger name (`None` = the default
/// logger) and the threshold.
///
/// # Errors
/// A message naming the accepted severities.
pub fn parse_log_level(value: &str) -> Result<(Option<String>, LogLevel), String> {
    let (logger, level) = match value.split_once(":=") {
        Some((l, v)) if !l.is_empty() => (Some(l.to_string()), v),
        Some(_) => return Err(format!("--log-level {value:?}: empty logger name")),
        None => (None, value),
    };
    let level = match level.to_ascii_lowercase().as_str() {
        "debug" => LogLevel::Debug,
        "info" => LogLevel::Info,
        "warn" | "warning" => LogLevel::Warn,
        "error" => LogLevel::Error,
        "fatal" => LogLevel::Fatal,
        _ => {
            return Err(format!(
                "--log-level {:?}: expected debug, info, warn, error or fatal (optionally LOGGER:=LEVEL)",
                printable(value, MAX_NAME_CHARS)
            ))
        }
    };
    Ok((logger, level))
}

/// One console line, without the newline; `at` before the epoch prints as 0.
pub fn line(level: LogLevel, at: SystemTime, node: &str, text: &str) -> String {
    let t = at.duration_since(UNIX_EPOCH).unwrap_or_default();
    format!(
        "[{}] [{}.{:09}] [{node}]: {text}",
        severity(level),
        t.as_secs(),
        t.subsec_nanos()
    )
}

/// Writes one line to standard error now, when `level` is at or above `threshold` (the
/// node's `--log-level`).
pub fn log(level: LogLevel, threshold: LogLevel, node: &str, text: &str) {
    if level >= threshold {
        eprintln!(
            "{}",
            line(
                level,
                SystemTime::now(),
                node,
                &printable(text, MAX_LOG_CHARS)
            )
        );
    }
}

/// The exit status of a node one of whose threads panicked (EX_SOFTWARE).
pub const PANIC_EXIT_STATUS: i32 = 70;

/// Makes a panic in any thread of the process fatal: after the default report (message,
/// location, backtrace if enabled) it logs which thread died and exits with
/// [`PANIC_EXIT_STATUS`], so that `ros2 launch` (respawn) or a service manager restarts the
/// node instead of leaving it running with a dead thread (the reception, the worker, or
/// RustDDS's discovery and event-loop threads). The node catches no panic anywhere, so a
/// panic is always a defect. For the node's programs only: a test process would end at its
/// first failed assertion.
pub fn exit_on_any_panic(node: &'static str) {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        default(info);
        let thread = std::thread::current();
        let what = info
            .payload()
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| info.payload().downcast_ref::<String>().cloned())
            .unwrap_or_default();
        eprintln!(
            "{}",
            line(
                LogLevel::Fatal,
                SystemTime::now(),
                node,
                &printable(
                    &format!(
                        "thread '{}' died: {what}; exiting with status {PANIC_EXIT_STATUS} so that the node is restarted",
                        thread.name().unwrap_or("unnamed")
                    ),
                    MAX_LOG_CHARS
                )
            )
        );
        std::process::exit(PANIC_EXIT_STATUS);
    }));
}

/// Longest text of one log line, characters: longer text is clipped (a request can carry a
/// 100,000-character parameter name).
pub const MAX_LOG_CHARS: usize = 2048;
/// Longest name (a parameter's, a topic's) quoted in a message, characters.
pub const MAX_NAME_CHARS: usize = 96;

/// `text` made safe to log: control characters escaped (a newline in a name must not forge
/// a log line of its own), clipped to `max` characters with the number left out.
pub fn printable(text: &str, max: usize) -> String {
    let mut out = String::new();
    let mut chars = text.chars();
    for (shown, c) in chars.by_ref().enumerate() {
        if shown == max {
            let rest = 1 + chars.count();
            out.push_str(&format!("... ({rest} more characters)"));
            return out;
        }
        if c.is_control() {
            out.extend(c.escape_default());
        } else {
            out.push(c);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn log_levels_parse_as_ros_takes_them() {
        assert_eq!(parse_log_level("WARN").unwrap(), (None, LogLevel::Warn));
        assert_eq!(parse_log_level("debug").unwrap(), (None, LogLevel::Debug));
        assert_eq!(
            parse_log_level("bevt_node:=error").unwrap(),
            (Some("bevt_node".to_string()), LogLevel::Error)
        );
        for bad in ["", "verbose", ":=info", "bevt_node:=", "info\n[FATAL]"] {
            let e = parse_log_level(bad).unwrap_err();
            assert!(e.contains("--log-level"), "{bad:?}: {e}");
            assert!(!e.contains('\n'), "{bad:?}: {e}");
        }
        assert!(LogLevel::Debug < LogLevel::Info && LogLevel::Error < LogLevel::Fatal);
    }

    #[test]
    fn logged_text_cannot_forge_lines_or_flood_the_log() {
        let forged = "x\n[INFO] [0.0] [bevt_node]: forged\r\u{1b}[2J";
        let p = printable(forged, 100);
        assert!(
            !p.contains('\n') && !p.contains('\r') && !p.contains('\u{1b}'),
            "{p}"
        );
        assert!(p.starts_with("x\\n[INFO]"), "{p}");
        let long = "a".repeat(120_072);
        let p = printable(&long, MAX_NAME_CHARS);
        assert_eq!(p, format!("{}... (119976 more characters)", "a".repeat(96)));
        assert_eq!(printable("exactly", 7), "exactly");
        assert_eq!(printable("äöü", 2), "äö... (1 more characters)");
    }

    #[test]
    fn lines_read_like_ros2_console_output() {
        let at = UNIX_EPOCH + Duration::new(1_732_473_600, 123_456_789);
        assert_eq!(
            line(LogLevel::Info, at, "bevt_node", "started"),
            "[INFO] [1732473600.123456789] [bevt_node]: started"
        );
        let early = UNIX_EPOCH + Duration::new(5, 7);
        assert_eq!(
            line(LogLevel::Warn, early, "n", "x"),
            "[WARN] [5.000000007] [n]: x"
        );
        assert_eq!(
            line(
                LogLevel::Error,
                UNIX_EPOCH - Duration::from_secs(1),
                "n",
                "x"
            ),
            "[ERROR] [0.000000000] [n]: x"
        );
        assert_eq!(severity(LogLevel::Debug), "DEBUG");
        assert_eq!(severity(LogLevel::Fatal), "FATAL");
    }
}
