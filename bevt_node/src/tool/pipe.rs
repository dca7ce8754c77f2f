//! `bevt ... | head`: when the reader of standard output goes away, the tool stops quietly
//! like other command-line programs instead of panicking in `println!`.
//!
//! Rust ignores SIGPIPE, so a write to a closed pipe fails and `println!` panics with
//! "failed printing to stdout: Broken pipe". [`exit_quietly_on_broken_pipe`] installs a panic
//! hook that turns exactly that panic into a silent exit with [`BROKEN_PIPE_EXIT`]; every
//! other panic still goes to the previous hook.

/// Exit status after a broken pipe: what a shell reports for a program killed by SIGPIPE.
pub const BROKEN_PIPE_EXIT: i32 = 141;

/// True for the panic message of a `print!`/`println!` to a closed pipe.
fn is_broken_pipe(message: &str) -> bool {
    message.starts_with("failed printing to std") && message.contains("Broken pipe")
}

/// Installs the hook (once per process; later calls add nothing harmful).
pub fn exit_quietly_on_broken_pipe() {
    let previous = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let payload = info.payload();
        let message = payload
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| payload.downcast_ref::<&str>().copied())
            .unwrap_or("");
        if is_broken_pipe(message) {
            std::process::exit(BROKEN_PIPE_EXIT);
        }
        previous(info);
    }));
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Read;
    use std::process::{Command, Stdio};

    const CHILD: &str = "BEVT_PIPE_TEST_CHILD";

    #[test]
    fn a_closed_stdout_ends_the_program_quietly() {
        if std::env::var_os(CHILD).is_some() {
            exit_quietly_on_broken_pipe();
            loop {
                println!("a line for a reader that has gone");
            }
        }
        let mut child = Command::new(std::env::current_exe().unwrap())
            .args([
                "--exact",
                "tool::pipe::tests::a_closed_stdout_ends_the_program_quietly",
                "--nocapture",
                "--test-threads=1",
            ])
            .env(CHILD, "1")
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let mut stdout = child.stdout.take().unwrap();
        let mut first = [0u8; 256];
        stdout.read_exact(&mut first).unwrap();
        drop(stdout);
        let mut stderr = String::new();
        child
            .stderr
            .take()
            .unwrap()
            .read_to_string(&mut stderr)
            .unwrap();
        let status = child.wait().unwrap();
        assert!(!stderr.contains("panicked"), "{stderr}");
        assert_eq!(status.code(), Some(BROKEN_PIPE_EXIT), "{stderr}");
    }

    #[test]
    fn only_the_broken_pipe_panic_is_quiet() {
        assert!(is_broken_pipe(
            "failed printing to stdout: Broken pipe (os error 32)"
        ));
        assert!(!is_broken_pipe("failed printing to stdout: No space left"));
        assert!(!is_broken_pipe("index out of bounds"));
    }
}
