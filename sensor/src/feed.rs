//! Where the sensor's events come from, as the actor sees them: the lines
//! of a trace file (paced by the actor), standard input as it comes (a
//! pipe, `tail -f`), and whatever producers send on the ingest key until
//! the stream finishes (never, while it is `live`). Reading is I/O and lives here; what
//! a line is worth is [`crate::ingest`]'s to decide.

use idmesh_protocol::trace::Line;
use std::io::BufRead;
use tokio::sync::mpsc;

/// A line of standard input with its number in the whole input (the
/// header is line 1), or why reading stopped.
pub type InputLine = Result<(usize, String), String>;

/// What the sensor streams, beside what producers send on the ingest key.
#[derive(Debug, Default)]
pub struct Source {
    /// A trace file's events (header excluded), paced by the actor.
    pub lines: Vec<Line>,
    /// Lines of standard input as they come; closed at its end.
    pub input: Option<mpsc::Receiver<InputLine>>,
}

/// Lines in flight between the reading thread and the actor: enough to
/// keep a fast pipe busy, few enough that a producer faster than the
/// leaders is held back by the pipe rather than by the sensor's memory.
const IN_FLIGHT: usize = 4096;

/// Reads `input` line by line on a thread of its own (a blocking read must
/// not hold the runtime), numbering lines from `first`.
pub fn lines_of<R: BufRead + Send + 'static>(
    mut input: R,
    first: usize,
) -> mpsc::Receiver<InputLine> {
    let (send, receive) = mpsc::channel(IN_FLIGHT);
    std::thread::spawn(move || {
        let mut number = first;
        loop {
            let mut text = String::new();
            let read = match input.read_line(&mut text) {
                Ok(0) => return,
                Ok(_) => Ok((number, text)),
                Err(e) => Err(format!("stdin:{number}: cannot read: {e}")),
            };
            let stop = read.is_err();
            if send.blocking_send(read).is_err() || stop {
                return;
            }
            number += 1;
        }
    });
    receive
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn input_lines_come_numbered_in_order_and_the_channel_closes_at_the_end() {
        let input = std::io::Cursor::new(b"first\nsecond\r\nlast without newline".to_vec());
        let mut lines = lines_of(input, 2);
        let mut got = Vec::new();
        while let Some(line) = lines.blocking_recv() {
            got.push(line.expect("readable"));
        }
        let numbers: Vec<usize> = got.iter().map(|(n, _)| *n).collect();
        assert_eq!(numbers, [2, 3, 4]);
        assert_eq!(got[0].1, "first\n");
        assert_eq!(got[2].1, "last without newline");
    }
}
