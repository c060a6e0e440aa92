//! One test per rule of the spec: each feeds a trace with exactly one bad
//! line and asserts the exact `FILE:LINE: reason` it gets.

use super::*;

/// 4 tracks, 2 red: the header most tests start from.
const H: &str = r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":4,"red":2}"#;
/// The same field, with identities.
const HI: &str =
    r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":4,"identities":4}"#;

/// Every line of a trace, or the first error as text.
fn read(trace: &str) -> Result<Vec<NumberedLine>, String> {
    TraceReader::new(trace.as_bytes(), "run.jsonl")
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| e.to_string())
}

fn error(trace: &str) -> String {
    match read(trace) {
        Ok(lines) => panic!("expected an error, read {} lines", lines.len()),
        Err(e) => e,
    }
}

/// The error for `line` as the second line, after the standard header.
fn bad(line: &str) -> String {
    error(&format!("{H}\n{line}\n"))
}

/// The error for a header alone.
fn bad_header(line: &str) -> String {
    error(&format!("{line}\n"))
}

fn header(extra: &str) -> String {
    format!(r#"{{"kind":"header","format":"idmesh-trace","version":1,"tracks":4{extra}}}"#)
}

/// A line that is valid on its own checked through the writer, which is the
/// only way to get values JSON cannot hold (NaN, infinities) to the rules.
fn write_error(line: Line) -> String {
    let mut writer = TraceWriter::new(Vec::new(), "out.jsonl");
    let header: Line = Header {
        red: Some(2),
        ..Header::new(4)
    }
    .into();
    writer.write(&header).unwrap();
    writer.write(&line).unwrap_err().to_string()
}

// ---- the shape of a line ----

#[test]
fn the_example_of_the_brief() {
    assert_eq!(
        error(&format!(
            "{H}\n{}\n{}\n{}\n{}\n{}\n{}\n",
            r#"{"kind":"mix","time":0,"a":0,"b":1,"swap":0.5}"#,
            r#"{"kind":"mix","time":1,"a":1,"b":2,"swap":0.5}"#,
            r#"{"kind":"move","time":1,"track":1,"x":0,"y":0}"#,
            r#"{"kind":"observe","time":2,"track":1,"red":0.8,"blue":0.2}"#,
            r#"{"kind":"mix","time":2,"a":1,"b":3,"swap":0.5}"#,
            r#"{"kind":"observe","time":3,"track":1,"red":-0.5,"blue":0.2}"#,
        )),
        "run.jsonl:7: observe: likelihood red = -0.5 is negative"
    );
}

#[test]
fn malformed_json() {
    assert_eq!(
        bad(r#"{"kind":"mix","time":0,"a":0,"b":1,"swap":}"#),
        "run.jsonl:2: malformed JSON: expected value (column 43)"
    );
}

#[test]
fn trailing_garbage_is_malformed() {
    assert_eq!(
        bad(r#"{"kind":"mix","time":0,"a":0,"b":1,"swap":0.5} x"#),
        "run.jsonl:2: malformed JSON: trailing characters (column 48)"
    );
}

#[test]
fn a_line_must_be_an_object() {
    assert_eq!(
        bad(" null"),
        "run.jsonl:2: a trace line must be a JSON object, got null"
    );
    assert_eq!(
        bad("[1, 2]"),
        "run.jsonl:2: a trace line must be a JSON object, got an array"
    );
    assert_eq!(
        bad("42"),
        "run.jsonl:2: a trace line must be a JSON object, got a number"
    );
}

#[test]
fn kind_given_twice_is_malformed() {
    assert_eq!(
        bad(r#"{"kind":"mix","kind":"observe","time":0}"#),
        "run.jsonl:2: malformed JSON: duplicate field `kind` (column 20)"
    );
}

#[test]
fn missing_kind() {
    assert_eq!(
        bad(r#"{"time":0,"a":0,"b":1,"swap":0.5}"#),
        "run.jsonl:2: the line has no `kind`"
    );
}

#[test]
fn kind_must_be_a_string() {
    assert_eq!(
        bad(r#"{"kind":3,"time":0}"#),
        "run.jsonl:2: `kind` must be a string, got 3"
    );
}

#[test]
fn unknown_kind() {
    assert_eq!(
        bad(r#"{"kind":"teleport","time":0,"track":1}"#),
        "run.jsonl:2: unknown kind \"teleport\" (expected header, mix, observe, identify, move, truth or detect)"
    );
}

#[test]
fn missing_field() {
    assert_eq!(
        bad(r#"{"kind":"mix","time":0,"a":0,"b":1}"#),
        "run.jsonl:2: mix: missing field `swap`"
    );
}

#[test]
fn wrong_type_of_field() {
    assert_eq!(
        bad(r#"{"kind":"observe","time":0,"track":-1,"red":1,"blue":1}"#),
        "run.jsonl:2: observe: invalid value: integer `-1`, expected u32 (column 37)"
    );
}

#[test]
fn blank_line_is_an_error() {
    assert_eq!(
        error(&format!(
            "{H}\n\n{}\n",
            r#"{"kind":"mix","time":0,"a":0,"b":1,"swap":0.5}"#
        )),
        "run.jsonl:2: empty line: a trace has one JSON object per line"
    );
    // Two newlines at the end are a blank last line.
    assert_eq!(
        error(&format!("{H}\n\n")),
        "run.jsonl:2: empty line: a trace has one JSON object per line"
    );
    assert_eq!(
        error(&format!("{H}\n   \n")),
        "run.jsonl:2: empty line: a trace has one JSON object per line"
    );
}

#[test]
fn one_trailing_newline_or_none_and_crlf_are_fine() {
    let mix = r#"{"kind":"mix","time":0,"a":0,"b":1,"swap":0.5}"#;
    assert_eq!(read(&format!("{H}\n{mix}\n")).unwrap().len(), 2);
    assert_eq!(read(&format!("{H}\n{mix}")).unwrap().len(), 2);
    assert_eq!(read(&format!("{H}\r\n{mix}\r\n")).unwrap().len(), 2);
}

#[test]
fn invalid_utf8_is_reported_at_its_line() {
    let mut trace = format!("{H}\n").into_bytes();
    trace.extend_from_slice(b"{\"kind\":\"mix\xff\"}\n");
    let err = TraceReader::new(&trace[..], "run.jsonl")
        .collect::<Result<Vec<_>, _>>()
        .unwrap_err();
    assert!(matches!(err, TraceError::Io { line: 2, .. }), "{err}");
    assert!(err.to_string().starts_with("run.jsonl:2: "), "{err}");
}

// ---- the header ----

#[test]
fn empty_trace() {
    assert_eq!(
        error(""),
        "run.jsonl:1: the trace is empty: it must start with a header line"
    );
}

#[test]
fn header_must_come_first() {
    assert_eq!(
        error(r#"{"kind":"mix","time":0,"a":0,"b":1,"swap":0.5}"#),
        "run.jsonl:1: mix: the first line must be the header"
    );
}

#[test]
fn only_one_header() {
    assert_eq!(
        bad(H),
        "run.jsonl:2: header: a trace has exactly one header, and line 1 already is it"
    );
}

#[test]
fn header_format() {
    assert_eq!(
        bad_header(r#"{"kind":"header","format":"other","version":1,"tracks":4}"#),
        "run.jsonl:1: header: format is \"other\", expected \"idmesh-trace\""
    );
}

#[test]
fn header_version() {
    assert_eq!(
        bad_header(r#"{"kind":"header","format":"idmesh-trace","version":3,"tracks":4}"#),
        "run.jsonl:1: header: version 3 is not supported (this reader knows versions 1 and 2)"
    );
}

#[test]
fn header_required_fields() {
    assert_eq!(
        bad_header(r#"{"kind":"header","format":"idmesh-trace","version":1}"#),
        "run.jsonl:1: header: missing field `tracks`"
    );
}

#[test]
fn header_needs_a_track() {
    assert_eq!(
        bad_header(r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":0}"#),
        "run.jsonl:1: header: tracks = 0: there must be at least one track"
    );
}

#[test]
fn header_more_red_than_tracks() {
    assert_eq!(
        bad_header(&header(r#","red":5"#)),
        "run.jsonl:1: header: red = 5 but there are only 4 tracks (k must be <= n)"
    );
}

#[test]
fn header_initial_red_length_must_be_red() {
    assert_eq!(
        bad_header(&header(r#","red":2,"initial_red":[0,1,2]"#)),
        "run.jsonl:1: header: initial_red has 3 tracks but red = 2"
    );
}

#[test]
fn header_initial_red_alone_is_at_most_n() {
    assert_eq!(
        bad_header(&header(r#","initial_red":[0,1,2,3,0]"#)),
        "run.jsonl:1: header: initial_red has 5 tracks but there are only 4 tracks (k must be <= n)"
    );
}

#[test]
fn header_initial_red_in_range() {
    assert_eq!(
        bad_header(&header(r#","red":2,"initial_red":[0,4]"#)),
        "run.jsonl:1: header: initial_red = 4 is not a track: there are 4 tracks (0..4)"
    );
}

#[test]
fn header_initial_red_distinct() {
    assert_eq!(
        bad_header(&header(r#","initial_red":[1,1]"#)),
        "run.jsonl:1: header: initial_red lists track 1 twice"
    );
}

#[test]
fn header_identities_one_per_track() {
    assert_eq!(
        bad_header(&header(r#","identities":3"#)),
        "run.jsonl:1: header: identities = 3 but there are 4 tracks (one identity per track)"
    );
}

#[test]
fn header_initial_identity_length() {
    assert_eq!(
        bad_header(&header(r#","identities":4,"initial_identity":[0,1,2]"#)),
        "run.jsonl:1: header: initial_identity has 3 entries, expected one per track (4)"
    );
}

#[test]
fn header_initial_identity_in_range() {
    assert_eq!(
        bad_header(&header(r#","identities":4,"initial_identity":[0,1,2,4]"#)),
        "run.jsonl:1: header: initial_identity[3] = 4 is not an identity: there are 4 (0..4)"
    );
}

#[test]
fn header_initial_identity_is_a_permutation() {
    assert_eq!(
        bad_header(&header(r#","identities":4,"initial_identity":[2,1,2,0]"#)),
        "run.jsonl:1: header: initial_identity gives identity 2 to both track 0 and track 2"
    );
}

#[test]
fn header_optional_fields_and_unknown_fields() {
    let lines = read(&format!(
        "{}\n",
        header(
            r#","red":2,"initial_red":[3,1],"identities":4,"initial_identity":[3,2,1,0],"source":"sim","description":"d","seed":7"#
        )
    ))
    .unwrap();
    let Line::Header(h) = &lines[0].line else {
        panic!("not a header")
    };
    assert_eq!(h.red_count(), Some(2));
    assert_eq!(h.initial_red.as_deref(), Some(&[3, 1][..]));
    assert_eq!(h.source.as_deref(), Some("sim"));
    // initial_red alone fixes k.
    let lines = read(&format!("{}\n", header(r#","initial_red":[2]"#))).unwrap();
    let Line::Header(h) = &lines[0].line else {
        panic!("not a header")
    };
    assert_eq!(h.red, None);
    assert_eq!(h.red_count(), Some(1));
}

// ---- times ----

#[test]
fn times_never_go_back() {
    assert_eq!(
        error(&format!(
            "{H}\n{}\n{}\n{}\n",
            r#"{"kind":"mix","time":5,"a":0,"b":1,"swap":0.5}"#,
            r#"{"kind":"move","time":5,"track":0,"x":1,"y":2}"#,
            r#"{"kind":"observe","time":4.5,"track":0,"red":1,"blue":0}"#,
        )),
        "run.jsonl:4: observe: time 4.5 is before time 5 of line 3: times must be non-decreasing"
    );
}

#[test]
fn times_are_finite() {
    let line = Mix {
        time: f64::INFINITY,
        a: 0,
        b: 1,
        swap: 0.5,
    };
    assert_eq!(
        write_error(line.into()),
        "out.jsonl:2: mix: time = inf is not a finite number"
    );
}

#[test]
fn time_is_required() {
    assert_eq!(
        bad(r#"{"kind":"mix","a":0,"b":1,"swap":0.5}"#),
        "run.jsonl:2: mix: missing field `time`"
    );
}

// ---- mix ----

#[test]
fn mix_tracks_in_range() {
    assert_eq!(
        bad(r#"{"kind":"mix","time":0,"a":0,"b":4,"swap":0.5}"#),
        "run.jsonl:2: mix: b = 4 is not a track: there are 4 tracks (0..4)"
    );
    assert_eq!(
        bad(r#"{"kind":"mix","time":0,"a":9,"b":0,"swap":0.5}"#),
        "run.jsonl:2: mix: a = 9 is not a track: there are 4 tracks (0..4)"
    );
}

#[test]
fn mix_tracks_distinct() {
    assert_eq!(
        bad(r#"{"kind":"mix","time":0,"a":2,"b":2,"swap":0.5}"#),
        "run.jsonl:2: mix: a = b = 2: a mix needs two distinct tracks"
    );
}

#[test]
fn mix_swap_is_a_probability() {
    assert_eq!(
        bad(r#"{"kind":"mix","time":0,"a":0,"b":1,"swap":1.5}"#),
        "run.jsonl:2: mix: swap = 1.5 is not a probability in [0, 1]"
    );
    assert_eq!(
        bad(r#"{"kind":"mix","time":0,"a":0,"b":1,"swap":-0.1}"#),
        "run.jsonl:2: mix: swap = -0.1 is not a probability in [0, 1]"
    );
    let nan = Mix {
        time: 0.0,
        a: 0,
        b: 1,
        swap: f64::NAN,
    };
    assert_eq!(
        write_error(nan.into()),
        "out.jsonl:2: mix: swap = NaN is not a probability in [0, 1]"
    );
}

// ---- observe ----

#[test]
fn observe_track_in_range() {
    assert_eq!(
        bad(r#"{"kind":"observe","time":0,"track":7,"red":0.8,"blue":0.2}"#),
        "run.jsonl:2: observe: track = 7 is not a track: there are 4 tracks (0..4)"
    );
}

#[test]
fn observe_likelihoods_not_negative() {
    assert_eq!(
        bad(r#"{"kind":"observe","time":0,"track":1,"red":-0.5,"blue":0.2}"#),
        "run.jsonl:2: observe: likelihood red = -0.5 is negative"
    );
    assert_eq!(
        bad(r#"{"kind":"observe","time":0,"track":1,"red":0.5,"blue":-2}"#),
        "run.jsonl:2: observe: likelihood blue = -2 is negative"
    );
}

#[test]
fn observe_likelihoods_finite() {
    let line = Observe {
        time: 0.0,
        track: 1,
        red: 0.5,
        blue: f64::NAN,
        sensor: None,
    };
    assert_eq!(
        write_error(line.into()),
        "out.jsonl:2: observe: likelihood blue = NaN is not a finite number"
    );
    assert_eq!(
        bad(r#"{"kind":"observe","time":0,"track":1,"red":1e400,"blue":1}"#),
        "run.jsonl:2: malformed JSON: number out of range (column 48)"
    );
}

#[test]
fn observe_likelihoods_not_both_zero() {
    assert_eq!(
        bad(r#"{"kind":"observe","time":0,"track":1,"red":0,"blue":0.0}"#),
        "run.jsonl:2: observe: likelihoods red and blue are both 0: the observation is impossible either way"
    );
}

// ---- identify ----

fn bad_identify(line: &str) -> String {
    error(&format!("{HI}\n{line}\n"))
}

#[test]
fn identify_needs_identities() {
    assert_eq!(
        bad(r#"{"kind":"identify","time":0,"track":1,"identity":2,"accuracy":0.9}"#),
        "run.jsonl:2: identify: the header declares no identities"
    );
}

#[test]
fn identify_track_in_range() {
    assert_eq!(
        bad_identify(r#"{"kind":"identify","time":0,"track":4,"identity":2,"accuracy":0.9}"#),
        "run.jsonl:2: identify: track = 4 is not a track: there are 4 tracks (0..4)"
    );
}

#[test]
fn identify_identity_in_range() {
    assert_eq!(
        bad_identify(r#"{"kind":"identify","time":0,"track":1,"identity":4,"accuracy":0.9}"#),
        "run.jsonl:2: identify: identity = 4 is out of range: there are 4 identities (0..4)"
    );
}

#[test]
fn identify_accuracy_in_half_open_unit_interval() {
    assert_eq!(
        bad_identify(r#"{"kind":"identify","time":0,"track":1,"identity":2,"accuracy":0}"#),
        "run.jsonl:2: identify: accuracy = 0 is not in (0, 1]"
    );
    assert_eq!(
        bad_identify(r#"{"kind":"identify","time":0,"track":1,"identity":2,"accuracy":1.01}"#),
        "run.jsonl:2: identify: accuracy = 1.01 is not in (0, 1]"
    );
    assert!(read(&format!(
        "{HI}\n{}\n",
        r#"{"kind":"identify","time":0,"track":1,"identity":2,"accuracy":1}"#
    ))
    .is_ok());
}

// ---- move ----

#[test]
fn move_track_in_range() {
    assert_eq!(
        bad(r#"{"kind":"move","time":0,"track":5,"x":1,"y":2}"#),
        "run.jsonl:2: move: track = 5 is not a track: there are 4 tracks (0..4)"
    );
}

#[test]
fn move_position_finite() {
    let line = Move {
        time: 0.0,
        track: 1,
        x: 0.0,
        y: f64::NEG_INFINITY,
    };
    assert_eq!(
        write_error(line.into()),
        "out.jsonl:2: move: y = -inf is not a finite number"
    );
}

// ---- truth ----

#[test]
fn truth_carries_something() {
    assert_eq!(
        bad(r#"{"kind":"truth","time":0}"#),
        "run.jsonl:2: truth: carries neither red nor identity"
    );
}

#[test]
fn truth_red_has_k_tracks() {
    assert_eq!(
        bad(r#"{"kind":"truth","time":0,"red":[1]}"#),
        "run.jsonl:2: truth: red has 1 tracks but the header says k = 2"
    );
}

#[test]
fn truth_red_in_range() {
    assert_eq!(
        bad(r#"{"kind":"truth","time":0,"red":[1,4]}"#),
        "run.jsonl:2: truth: red = 4 is not a track: there are 4 tracks (0..4)"
    );
}

#[test]
fn truth_red_distinct() {
    assert_eq!(
        bad(r#"{"kind":"truth","time":0,"red":[3,3]}"#),
        "run.jsonl:2: truth: red lists track 3 twice"
    );
}

#[test]
fn truth_red_any_size_when_k_unknown() {
    let lines = read(&format!(
        "{}\n{}\n",
        header(""),
        r#"{"kind":"truth","time":0,"red":[0,1,3]}"#
    ))
    .unwrap();
    assert_eq!(lines.len(), 2);
}

#[test]
fn truth_identity_is_a_permutation() {
    assert_eq!(
        bad(r#"{"kind":"truth","time":0,"identity":[0,1,2]}"#),
        "run.jsonl:2: truth: identity has 3 entries, expected one per track (4)"
    );
    assert_eq!(
        bad(r#"{"kind":"truth","time":0,"identity":[0,1,2,9]}"#),
        "run.jsonl:2: truth: identity[3] = 9 is not an identity: there are 4 (0..4)"
    );
    assert_eq!(
        bad(r#"{"kind":"truth","time":0,"identity":[0,1,0,3]}"#),
        "run.jsonl:2: truth: identity gives identity 0 to both track 0 and track 2"
    );
}

// ---- reading and writing ----

#[test]
fn unknown_fields_are_ignored() {
    let lines = read(&format!(
        "{H}\n{}\n",
        r#"{"kind":"observe","time":0,"track":1,"red":0.8,"blue":0.2,"confidence":"high","pixels":[1,2]}"#
    ))
    .unwrap();
    assert_eq!(
        lines[1],
        NumberedLine {
            number: 2,
            line: Line::Observe(Observe {
                time: 0.0,
                track: 1,
                red: 0.8,
                blue: 0.2,
                sensor: None
            })
        }
    );
}

#[test]
fn kind_is_written_first_and_absent_fields_are_left_out() {
    let mut writer = TraceWriter::new(Vec::new(), "out.jsonl");
    writer.write(&Header::new(3).into()).unwrap();
    writer
        .write(
            &Truth {
                time: 1.5,
                red: Some(vec![2]),
                identity: None,
            }
            .into(),
        )
        .unwrap();
    let text = String::from_utf8(writer.finish().unwrap()).unwrap();
    assert_eq!(
        text,
        concat!(
            r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":3}"#,
            "\n",
            r#"{"kind":"truth","time":1.5,"red":[2]}"#,
            "\n"
        )
    );
}

#[test]
fn writer_rejects_what_the_reader_would() {
    let mut writer = TraceWriter::new(Vec::new(), "out.jsonl");
    let mix = Mix {
        time: 0.0,
        a: 0,
        b: 1,
        swap: 0.5,
    };
    assert_eq!(
        writer.write(&mix.into()).unwrap_err().to_string(),
        "out.jsonl:1: mix: the first line must be the header"
    );
    assert_eq!(writer.lines(), 0);
    assert_eq!(
        TraceWriter::new(Vec::new(), "out.jsonl")
            .finish()
            .unwrap_err()
            .to_string(),
        "out.jsonl:1: the trace is empty: it must start with a header line"
    );
}

#[test]
fn round_trip_writer_to_reader() {
    let lines: Vec<Line> = vec![
        Header {
            red: Some(2),
            initial_red: Some(vec![0, 3]),
            identities: Some(5),
            initial_identity: Some(vec![4, 3, 2, 1, 0]),
            source: Some("round trip".into()),
            description: Some("every kind of line".into()),
            ..Header::new(5)
        }
        .into(),
        Mix {
            time: 0.25,
            a: 0,
            b: 2,
            swap: 0.5,
        }
        .into(),
        Observe {
            time: 1.0,
            track: 2,
            red: 0.8,
            blue: 0.2,
            sensor: Some("cam-1".into()),
        }
        .into(),
        Observe {
            time: 1.0,
            track: 4,
            red: 0.1,
            blue: 0.7,
            sensor: None,
        }
        .into(),
        Identify {
            time: 2.0,
            track: 1,
            identity: 3,
            accuracy: 0.95,
        }
        .into(),
        Move {
            time: 2.5,
            track: 3,
            x: -1.25,
            y: 1e6,
        }
        .into(),
        Truth {
            time: 3.0,
            red: Some(vec![2, 3]),
            identity: Some(vec![4, 3, 1, 2, 0]),
        }
        .into(),
        Truth {
            time: 3.0,
            red: None,
            identity: Some(vec![0, 1, 2, 3, 4]),
        }
        .into(),
    ];
    let mut writer = TraceWriter::new(Vec::new(), "out.jsonl");
    for line in &lines {
        writer.write(line).unwrap();
    }
    assert_eq!(writer.lines(), lines.len());
    let bytes = writer.finish().unwrap();
    let mut reader = TraceReader::new(&bytes[..], "out.jsonl");
    assert_eq!(reader.read_header().unwrap(), {
        let Line::Header(h) = &lines[0] else {
            unreachable!()
        };
        h.clone()
    });
    let rest: Vec<NumberedLine> = reader.by_ref().collect::<Result<_, _>>().unwrap();
    let read: Vec<Line> = rest.iter().map(|l| l.line.clone()).collect();
    assert_eq!(read, lines[1..]);
    let numbers: Vec<usize> = rest.iter().map(|l| l.number).collect();
    assert_eq!(numbers, (2..=lines.len()).collect::<Vec<_>>());
    assert!(reader.header().is_some());
    // The derived decoder agrees with the validating one.
    for (text, line) in String::from_utf8(bytes).unwrap().lines().zip(&lines) {
        assert_eq!(&serde_json::from_str::<Line>(text).unwrap(), line);
    }
}

#[test]
fn read_all_gives_the_header_and_the_lines_after_it_or_the_first_error() {
    let trace = format!(
        "{H}\n{}\n{}\n",
        r#"{"kind":"mix","time":1,"a":0,"b":1,"swap":0.5}"#,
        r#"{"kind":"observe","time":2,"track":2,"red":0.8,"blue":0.2}"#
    );
    let (header, lines) = TraceReader::new(trace.as_bytes(), "run.jsonl")
        .read_all()
        .unwrap();
    assert_eq!(header.tracks, 4);
    assert_eq!(
        lines.iter().map(Line::kind).collect::<Vec<_>>(),
        ["mix", "observe"]
    );
    let broken = format!("{H}\n{{\n");
    let err = TraceReader::new(broken.as_bytes(), "run.jsonl")
        .read_all()
        .unwrap_err();
    assert!(err.to_string().starts_with("run.jsonl:2: "), "{err}");
}

#[test]
fn reader_stops_after_the_first_error() {
    let trace = format!(
        "{H}\n{}\n{}\n",
        r#"{"kind":"mix","time":0,"a":0,"b":0,"swap":0.5}"#,
        r#"{"kind":"mix","time":0,"a":0,"b":1,"swap":0.5}"#
    );
    let mut reader = TraceReader::new(trace.as_bytes(), "run.jsonl");
    assert!(reader.next().unwrap().is_ok());
    let err = reader.next().unwrap().unwrap_err();
    assert_eq!(err.line(), 2);
    assert_eq!(err.file(), "run.jsonl");
    assert_eq!(err.problem(), Some(&Problem::SelfMix(0)));
    assert!(reader.next().is_none());
}

#[test]
fn an_event_is_every_line_but_the_header_and_the_truth() {
    let lines = read(&format!(
        "{}\n{}\n{}\n{}\n{}\n{}\n",
        header(r#","identities":4"#),
        r#"{"kind":"mix","time":1,"a":0,"b":1,"swap":0.5}"#,
        r#"{"kind":"observe","time":1,"track":0,"red":1,"blue":0}"#,
        r#"{"kind":"identify","time":1,"track":0,"identity":1,"accuracy":0.9}"#,
        r#"{"kind":"move","time":1,"track":0,"x":1,"y":2}"#,
        r#"{"kind":"truth","time":2,"identity":[1,0,2,3]}"#,
    ))
    .unwrap();
    let events: Vec<bool> = lines.iter().map(|l| l.line.is_event()).collect();
    assert_eq!(events, [false, true, true, true, true, false]);
}

// ---- version 2: the detect line ----

/// 4 tracks, identities, version 2.
const H2: &str =
    r#"{"kind":"header","format":"idmesh-trace","version":2,"tracks":4,"identities":4}"#;

fn bad2(line: &str) -> String {
    error(&format!("{H2}\n{line}\n"))
}

#[test]
fn a_version_1_trace_reads_unchanged() {
    let lines = read(&format!(
        "{H}\n{}\n{}\n",
        r#"{"kind":"move","time":0,"track":1,"x":2.5,"y":-1}"#,
        r#"{"kind":"mix","time":1,"a":0,"b":1,"swap":0.5}"#
    ))
    .unwrap();
    assert_eq!(lines.len(), 3);
    match &lines[0].line {
        Line::Header(h) => assert_eq!(h.version, VERSION),
        other => panic!("{other:?}"),
    }
    assert_eq!(
        Header::new(4).version,
        1,
        "the default header stays version 1"
    );
}

#[test]
fn detect_lines_read_in_version_2() {
    let lines = read(&format!(
        "{H2}\n{}\n{}\n{}\n",
        r#"{"kind":"detect","time":0,"track":1,"x":2.5,"y":-1}"#,
        r#"{"kind":"detect","time":0.1,"track":2,"x":0,"y":0,"scores":{"red":0.83,"blue":0.17}}"#,
        r#"{"kind":"detect","time":0.2,"track":3,"x":0,"y":0,"identity":2,"accuracy":0.9}"#
    ))
    .unwrap();
    let Line::Detect(d) = &lines[2].line else {
        panic!("{:?}", lines[2].line)
    };
    assert_eq!(d.scores.as_ref().unwrap()["red"], 0.83);
    let Line::Detect(d) = &lines[3].line else {
        panic!("{:?}", lines[3].line)
    };
    assert_eq!((d.identity, d.accuracy), (Some(2), Some(0.9)));
    // Written back the same way.
    let text = serde_json::to_string(&lines[2].line).unwrap();
    assert_eq!(
        text,
        r#"{"kind":"detect","time":0.1,"track":2,"x":0.0,"y":0.0,"scores":{"blue":0.17,"red":0.83}}"#
    );
}

#[test]
fn detect_needs_version_2() {
    assert_eq!(
        bad(r#"{"kind":"detect","time":0,"track":1,"x":0,"y":0}"#),
        "run.jsonl:2: detect: a version-1 trace has no detect lines (they need version 2)"
    );
}

#[test]
fn detect_rules() {
    let cases = [
        (
            r#"{"kind":"detect","time":0,"track":9,"x":0,"y":0}"#,
            "run.jsonl:2: detect: track = 9 is not a track: there are 4 tracks (0..4)",
        ),
        (
            r#"{"kind":"detect","time":0,"track":1,"x":0,"y":0,"scores":{}}"#,
            "run.jsonl:2: detect: scores is empty: leave it out when there are no scores",
        ),
        (
            r#"{"kind":"detect","time":0,"track":1,"x":0,"y":0,"scores":{"red":1.2,"blue":-0.2}}"#,
            "run.jsonl:2: detect: score \"blue\" = -0.2 is not a number in [0, 1]",
        ),
        (
            r#"{"kind":"detect","time":0,"track":1,"x":0,"y":0,"scores":{"red":0.5,"blue":0.4}}"#,
            "run.jsonl:2: detect: scores sum to 0.9, not 1 (tolerance 0.01)",
        ),
        (
            r#"{"kind":"detect","time":0,"track":1,"x":0,"y":0,"identity":1}"#,
            "run.jsonl:2: detect: an identity read needs both identity and accuracy",
        ),
        (
            r#"{"kind":"detect","time":0,"track":1,"x":0,"y":0,"identity":7,"accuracy":0.9}"#,
            "run.jsonl:2: detect: identity = 7 is out of range: there are 4 identities (0..4)",
        ),
        (
            r#"{"kind":"detect","time":0,"track":1,"x":0,"y":0,"identity":1,"accuracy":0}"#,
            "run.jsonl:2: detect: accuracy = 0 is not in (0, 1]",
        ),
        (
            r#"{"kind":"detect","time":0,"track":1,"x":"a","y":0}"#,
            "run.jsonl:2: detect: invalid type: string \"a\", expected f64 (column 43)",
        ),
    ];
    for (line, want) in cases {
        assert_eq!(bad2(line), want, "{line}");
    }
    let no_identities = r#"{"kind":"header","format":"idmesh-trace","version":2,"tracks":4}"#;
    assert_eq!(
        error(&format!(
            "{no_identities}\n{}\n",
            r#"{"kind":"detect","time":0,"track":1,"x":0,"y":0,"identity":1,"accuracy":0.9}"#
        )),
        "run.jsonl:2: detect: an identity read needs a header that declares identities"
    );
}

#[test]
fn detect_positions_must_be_finite() {
    let mut writer = TraceWriter::new(Vec::new(), "out.jsonl");
    writer.write(&Header::new_v2(4).into()).unwrap();
    let err = writer
        .write(&Detect::at(0.0, 1, f64::NAN, 0.0).into())
        .unwrap_err()
        .to_string();
    assert_eq!(err, "out.jsonl:2: detect: x = NaN is not a finite number");
}
