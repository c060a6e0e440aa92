//! Reading a trace: lines in, validated [`Line`]s with their numbers out,
//! or the first error as `FILE:LINE: reason`.

use super::error::TraceError;
use super::line::{Header, Line};
use super::problem::Problem;
use super::validate::Validator;
use std::fs::File;
use std::io::{BufRead, BufReader};
use std::path::Path;

/// A valid line and its 1-based line number in the trace.
#[derive(Debug, Clone, PartialEq)]
pub struct NumberedLine {
    pub number: usize,
    pub line: Line,
}

/// Reads a trace from any [`BufRead`], one line at a time, checking every
/// rule of the spec. As an iterator it yields every line, the header first;
/// it stops after the first error.
///
/// Blank lines are errors (a trace has one object per line); only the
/// newline that ends the last line is allowed, and `\r\n` endings are
/// accepted.
pub struct TraceReader<R> {
    input: R,
    source: String,
    number: usize,
    text: String,
    validator: Validator,
    done: bool,
}

impl TraceReader<BufReader<File>> {
    /// Opens a trace file; its path (as given) names it in errors.
    pub fn open(path: impl AsRef<Path>) -> std::io::Result<Self> {
        let path = path.as_ref();
        let file = File::open(path)?;
        Ok(TraceReader::new(
            BufReader::new(file),
            path.display().to_string(),
        ))
    }
}

impl<R: BufRead> TraceReader<R> {
    /// A reader of `input`, which errors call `source` (e.g. its path).
    pub fn new(input: R, source: impl Into<String>) -> Self {
        TraceReader {
            input,
            source: source.into(),
            number: 0,
            text: String::new(),
            validator: Validator::new(),
            done: false,
        }
    }

    /// The name errors give the trace.
    pub fn source(&self) -> &str {
        &self.source
    }

    /// The header, once it has been read.
    pub fn header(&self) -> Option<&Header> {
        self.validator.header()
    }

    /// Reads the first line, which must be the header, and returns it.
    pub fn read_header(&mut self) -> Result<Header, TraceError> {
        if let Some(header) = self.header() {
            return Ok(header.clone());
        }
        match self.next() {
            Some(Ok(NumberedLine {
                line: Line::Header(header),
                ..
            })) => Ok(header),
            // The validator accepts only a header first; kept total anyway.
            Some(Ok(other)) => Err(self.invalid(Problem::HeaderNotFirst {
                kind: other.line.kind(),
            })),
            Some(Err(error)) => Err(error),
            None => Err(self.invalid(Problem::Empty)),
        }
    }

    /// The header and every line after it, for a reader that wants the
    /// whole trace in memory (the lines without their numbers).
    pub fn read_all(mut self) -> Result<(Header, Vec<Line>), TraceError> {
        let header = self.read_header()?;
        let mut lines = Vec::new();
        while let Some(numbered) = self.read_line()? {
            lines.push(numbered.line);
        }
        Ok((header, lines))
    }

    /// The next valid line, `Ok(None)` at the end of the trace.
    pub fn read_line(&mut self) -> Result<Option<NumberedLine>, TraceError> {
        if self.done {
            return Ok(None);
        }
        let result = self.read_line_inner();
        if !matches!(result, Ok(Some(_))) {
            self.done = true;
        }
        result
    }

    fn read_line_inner(&mut self) -> Result<Option<NumberedLine>, TraceError> {
        self.text.clear();
        let read = self.input.read_line(&mut self.text);
        self.number += 1;
        match read {
            Err(cause) => Err(TraceError::Io {
                file: self.source.clone(),
                line: self.number,
                cause,
            }),
            Ok(0) => {
                // The end: no line `number` exists; an empty trace is
                // reported at line 1.
                self.number = self.number.saturating_sub(1);
                self.validator
                    .finish()
                    .map_err(|problem| self.invalid_at(self.number.max(1), problem))?;
                Ok(None)
            }
            Ok(_) => {
                let text = self.text.strip_suffix('\n').unwrap_or(&self.text);
                let text = text.strip_suffix('\r').unwrap_or(text);
                let line = Line::parse(text).map_err(|problem| self.invalid(problem))?;
                self.validator
                    .check(&line, self.number)
                    .map_err(|problem| self.invalid(problem))?;
                Ok(Some(NumberedLine {
                    number: self.number,
                    line,
                }))
            }
        }
    }

    fn invalid(&self, problem: Problem) -> TraceError {
        self.invalid_at(self.number, problem)
    }

    fn invalid_at(&self, line: usize, problem: Problem) -> TraceError {
        TraceError::Invalid {
            file: self.source.clone(),
            line,
            problem,
        }
    }
}

impl<R: BufRead> Iterator for TraceReader<R> {
    type Item = Result<NumberedLine, TraceError>;

    fn next(&mut self) -> Option<Self::Item> {
        self.read_line().transpose()
    }
}
