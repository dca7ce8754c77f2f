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

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

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
