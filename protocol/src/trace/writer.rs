//! Writing a trace: every line is checked by the same rules the reader
//! applies before it is written, so a simulator cannot produce a trace that
//! replay would reject.

use super::error::TraceError;
use super::line::Line;
use super::validate::Validator;
use std::io::Write;

/// Writes a trace as JSON Lines (`kind` first, absent optional fields left
/// out) to any [`Write`]. Wrap a file in a `BufWriter`; call
/// [`TraceWriter::finish`] at the end to flush and to check the trace had
/// its header.
pub struct TraceWriter<W: Write> {
    output: W,
    sink: String,
    number: usize,
    validator: Validator,
}

impl<W: Write> TraceWriter<W> {
    /// A writer to `output`, which errors call `sink` (e.g. its path).
    pub fn new(output: W, sink: impl Into<String>) -> Self {
        TraceWriter {
            output,
            sink: sink.into(),
            number: 0,
            validator: Validator::new(),
        }
    }

    /// How many lines have been written.
    pub fn lines(&self) -> usize {
        self.number
    }

    /// Checks and writes one line; the first must be the header. A rejected
    /// line is not written and does not count.
    pub fn write(&mut self, line: &Line) -> Result<(), TraceError> {
        let number = self.number + 1;
        self.validator
            .check(line, number)
            .map_err(|problem| TraceError::Invalid {
                file: self.sink.clone(),
                line: number,
                problem,
            })?;
        let io = |cause| TraceError::Io {
            file: self.sink.clone(),
            line: number,
            cause,
        };
        serde_json::to_writer(&mut self.output, line).map_err(|e| io(e.into()))?;
        self.output.write_all(b"\n").map_err(io)?;
        self.number = number;
        Ok(())
    }

    /// Flushes the output.
    pub fn flush(&mut self) -> Result<(), TraceError> {
        self.output.flush().map_err(|cause| TraceError::Io {
            file: self.sink.clone(),
            line: self.number,
            cause,
        })
    }

    /// Checks the trace is complete (it has its header), flushes it and
    /// hands the output back.
    pub fn finish(mut self) -> Result<W, TraceError> {
        self.validator
            .finish()
            .map_err(|problem| TraceError::Invalid {
                file: self.sink.clone(),
                line: 1,
                problem,
            })?;
        self.flush()?;
        Ok(self.output)
    }
}
