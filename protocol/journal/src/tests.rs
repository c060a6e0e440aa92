use super::*;
use proptest::prelude::*;
use std::path::Path;

const KIND: &str = "test-log";

/// A fresh folder for one test's files, removed when dropped.
fn dir(name: &str) -> tempfile::TempDir {
    tempfile::Builder::new()
        .prefix(&format!("idmesh-journal-{name}-"))
        .tempdir()
        .unwrap()
}

/// The bytes of a log of `payloads`.
fn bytes_of(generation: u64, payloads: &[Vec<u8>]) -> Vec<u8> {
    let mut bytes = header(KIND, generation).to_vec();
    for p in payloads {
        encode_record(&[p], &mut bytes);
    }
    bytes
}

fn payloads_of(contents: &Contents) -> Vec<Vec<u8>> {
    contents.records.iter().map(|r| r.payload.clone()).collect()
}

fn sample() -> Vec<Vec<u8>> {
    vec![
        b"first".to_vec(),
        Vec::new(),
        vec![7; 300],
        b"fourth".to_vec(),
        vec![1, 2, 3],
    ]
}

/// Where each record of `bytes_of(_, payloads)` starts.
fn offsets(payloads: &[Vec<u8>]) -> Vec<u64> {
    let mut at = HEADER_LEN as u64;
    payloads
        .iter()
        .map(|p| {
            let start = at;
            at += (RECORD_HEAD + p.len()) as u64;
            start
        })
        .collect()
}

fn parse_ok(bytes: &[u8]) -> Contents {
    parse(bytes, KIND, Path::new("test.log"))
        .unwrap()
        .expect("a header")
}

#[test]
fn records_come_back_in_order_and_appending_goes_on_after_them() {
    let scratch = dir("order");
    let dir = scratch.path();
    let path = dir.join("log");
    let mut writer = Writer::create(&[&path], KIND, 3, &[b"one".as_slice()]).unwrap();
    writer.append(&[b"tw", b"o"]).unwrap();
    writer.append_all(&[b"three".to_vec(), Vec::new()]).unwrap();
    writer.sync().unwrap();
    let length = writer.len();
    drop(writer);
    assert_eq!(std::fs::metadata(&path).unwrap().len(), length);
    let contents = read(&path, KIND).unwrap().unwrap();
    assert_eq!(contents.generation, 3);
    assert_eq!(contents.ending, Ending::Clean);
    assert_eq!(
        payloads_of(&contents),
        [
            b"one".to_vec(),
            b"two".to_vec(),
            b"three".to_vec(),
            Vec::new()
        ]
    );
    let mut writer = Writer::resume(&[&path], KIND, contents.end()).unwrap();
    writer.append(&[b"five"]).unwrap();
    drop(writer);
    assert_eq!(read(&path, KIND).unwrap().unwrap().records.len(), 5);
    // Replaced whole: a new generation, only what it was given.
    let mut writer = Writer::resume(&[&path], KIND, length + 16).unwrap();
    writer.replace(4, &[b"state"]).unwrap();
    writer.append(&[b"after"]).unwrap();
    drop(writer);
    let contents = read(&path, KIND).unwrap().unwrap();
    assert_eq!(contents.generation, 4);
    assert_eq!(
        payloads_of(&contents),
        [b"state".to_vec(), b"after".to_vec()]
    );
    assert!(!dir.join("log.tmp").exists());
    // No file, or one cut inside its header: nothing.
    assert_eq!(read(&dir.join("none"), KIND).unwrap(), None);
    let bytes = bytes_of(0, &[]);
    for cut in 0..HEADER_LEN {
        assert_eq!(
            parse(&bytes[..cut], KIND, Path::new("x")).unwrap(),
            None,
            "{cut}"
        );
    }
}

#[test]
fn every_torn_tail_is_cut_and_the_whole_records_before_it_kept() {
    let payloads = sample();
    let bytes = bytes_of(1, &payloads);
    let starts = offsets(&payloads);
    for cut in HEADER_LEN..=bytes.len() {
        let contents = parse_ok(&bytes[..cut]);
        let whole = starts
            .iter()
            .zip(&payloads)
            .filter(|(s, p)| **s as usize + RECORD_HEAD + p.len() <= cut)
            .count();
        assert_eq!(payloads_of(&contents), payloads[..whole], "cut at {cut}");
        let boundary = cut == bytes.len() || starts.contains(&(cut as u64));
        match contents.ending {
            Ending::Clean => assert!(boundary, "clean only at a record's end: {cut}"),
            Ending::Torn { at, bytes } => {
                assert!(!boundary, "{cut}");
                assert_eq!(at, contents.end());
                assert_eq!(at + bytes, cut as u64);
            }
            Ending::Damaged(d) => panic!("a torn tail taken for damage at {cut}: {d}"),
        }
    }
    // On disk: cut off, and the next record goes after the whole ones.
    let scratch = dir("torn");
    let dir = scratch.path();
    let path = dir.join("log");
    std::fs::write(&path, &bytes[..bytes.len() - 2]).unwrap();
    let contents = read(&path, KIND).unwrap().unwrap();
    assert_eq!(contents.records.len(), 4);
    let mut writer = Writer::resume(&[&path], KIND, contents.end()).unwrap();
    writer.append(&[&payloads[4]]).unwrap();
    drop(writer);
    assert_eq!(std::fs::read(&path).unwrap(), bytes);
}

#[test]
fn a_bad_last_record_is_torn_and_a_bad_one_in_the_middle_is_damage_naming_file_and_byte() {
    let payloads = sample();
    let starts = offsets(&payloads);
    let mut bytes = bytes_of(1, &payloads);
    let last = bytes.len() - 1;
    bytes[last] ^= 0x10;
    let contents = parse_ok(&bytes);
    assert_eq!(payloads_of(&contents), payloads[..4]);
    assert!(matches!(contents.ending, Ending::Torn { at, .. } if at == starts[4]));

    // The third record's payload, then its length.
    for (byte, problem) in [(RECORD_HEAD + 5, Problem::Checksum), (1, Problem::Head)] {
        let mut bytes = bytes_of(1, &payloads);
        bytes[starts[2] as usize + byte] ^= 0x01;
        let contents = parse(&bytes, KIND, Path::new("/state/leader-0.journal"))
            .unwrap()
            .unwrap();
        assert_eq!(payloads_of(&contents), payloads[..2]);
        let damage = contents.damage().expect("damage").clone();
        assert_eq!(damage.at, starts[2]);
        assert_eq!(damage.problem, problem);
        assert_eq!(damage.after, 2, "the two records after it are whole");
        assert_eq!(damage.records(), 3);
        assert_eq!(damage.bytes, bytes.len() as u64 - starts[2]);
        let said = damage.to_string();
        assert!(said.contains("/state/leader-0.journal"), "{said}");
        assert!(said.contains(&format!("at byte {}", starts[2])), "{said}");
    }

    // Bytes overwritten across two records: damage, the rest found.
    let mut bytes = bytes_of(1, &payloads);
    let from = starts[1] as usize + 3;
    bytes[from..from + 32].fill(0xab);
    let damage = parse_ok(&bytes).damage().cloned().expect("damage");
    assert_eq!((damage.at, damage.after), (starts[1], 2));
}

#[test]
fn a_damaged_header_and_other_formats_are_errors_naming_the_file() {
    let path = Path::new("/state/x.journal");
    let mut bytes = bytes_of(1, &sample());
    bytes[30] ^= 1;
    let error = parse(&bytes, KIND, path).unwrap_err().to_string();
    assert!(
        error.contains("/state/x.journal is damaged at byte 0"),
        "{error}"
    );

    let other = {
        let mut b = header("sensor-journal", 0).to_vec();
        encode_record(&[b"x"], &mut b);
        b
    };
    let error = parse(&other, KIND, path).unwrap_err().to_string();
    assert!(
        error.contains("holds a sensor-journal, not a test-log"),
        "{error}"
    );

    let mut newer = header(KIND, 0);
    newer[8] = 2;
    let sum = crc32fast::hash(&newer[..36]);
    newer[36..].copy_from_slice(&sum.to_le_bytes());
    let error = parse(&newer, KIND, path).unwrap_err().to_string();
    assert!(error.contains("journal format 2"), "{error}");

    // The formats before this one: what they were, and what to do.
    let mut old_leader = vec![4u8, 8, 0, 0, 0];
    old_leader.extend_from_slice(&0u64.to_le_bytes());
    for (bytes, what) in [
        (old_leader, "a leader journal"),
        (
            b"idmesh/1\0\0\0\0\0\0\0\0state".to_vec(),
            "a leader snapshot",
        ),
        (
            b"idmesh-sensor-journal/1\n\x01\0\0\0".to_vec(),
            "a sensor journal",
        ),
    ] {
        let error = parse(&bytes, KIND, path).unwrap_err();
        assert!(matches!(error, Error::OldFormat { .. }), "{error}");
        let said = error.to_string();
        assert!(
            said.contains(what) && said.contains("/state/x.journal"),
            "{said}"
        );
        assert!(
            said.contains("remove the deployment's state directory"),
            "{said}"
        );
    }
    let error = parse(b"not a journal at all, long enough to be one", KIND, path)
        .unwrap_err()
        .to_string();
    assert!(error.contains("is not an idmesh journal"), "{error}");
}

#[test]
fn a_record_damaged_in_one_copy_is_taken_from_the_other() {
    let scratch = dir("copies");
    let dir = scratch.path();
    let (path, copy) = (dir.join("log"), dir.join("log.copy"));
    let payloads = sample();
    let starts = offsets(&payloads);
    let mut writer = Writer::create(&[&path, &copy], KIND, 2, &payloads[..3]).unwrap();
    writer.append_all(&payloads[3..]).unwrap();
    writer.sync().unwrap();
    drop(writer);
    let good = std::fs::read(&path).unwrap();
    assert_eq!(std::fs::read(&copy).unwrap(), good);
    let merged = read_copies(&path, &copy, KIND).unwrap().unwrap();
    assert_eq!(payloads_of(&merged.contents), payloads);
    assert!(merged.repairs.is_empty() && !merged.rewrite);

    // Damaged in the first copy, and a later record in the second.
    let mut a = good.clone();
    a[starts[1] as usize + 2] ^= 0x40;
    let mut b = good.clone();
    b[starts[3] as usize + RECORD_HEAD] ^= 0x01;
    std::fs::write(&path, &a).unwrap();
    std::fs::write(&copy, &b).unwrap();
    let merged = read_copies(&path, &copy, KIND).unwrap().unwrap();
    assert_eq!(payloads_of(&merged.contents), payloads);
    assert_eq!(merged.contents.ending, Ending::Clean);
    let repaired: Vec<(&Path, u64)> = merged
        .repairs
        .iter()
        .map(|r| (r.path.as_path(), r.at))
        .collect();
    assert_eq!(
        repaired,
        [(path.as_path(), starts[1]), (copy.as_path(), starts[3])]
    );
    assert!(merged.rewrite);

    // The same record damaged in both: damage, naming both.
    let mut a = good.clone();
    a[starts[2] as usize + 2] ^= 0x40;
    let mut b = good.clone();
    b[starts[2] as usize + RECORD_HEAD + 1] ^= 0x01;
    std::fs::write(&path, &a).unwrap();
    std::fs::write(&copy, &b).unwrap();
    let merged = read_copies(&path, &copy, KIND).unwrap().unwrap();
    assert_eq!(payloads_of(&merged.contents), payloads[..2]);
    let said = merged.contents.damage().expect("damage").to_string();
    assert!(said.contains(&path.display().to_string()), "{said}");
    assert!(said.contains(&copy.display().to_string()), "{said}");
    assert!(said.contains(&format!("at byte {}", starts[2])), "{said}");

    // One copy missing, or behind (the process died between the two
    // writes), or torn: no damage, the longer whole one is taken.
    std::fs::remove_file(&copy).unwrap();
    std::fs::write(&path, &good).unwrap();
    let merged = read_copies(&path, &copy, KIND).unwrap().unwrap();
    assert_eq!(payloads_of(&merged.contents), payloads);
    assert!(merged.rewrite && merged.repairs.is_empty());
    std::fs::write(&copy, &good[..starts[4] as usize + 3]).unwrap();
    let merged = read_copies(&path, &copy, KIND).unwrap().unwrap();
    assert_eq!(payloads_of(&merged.contents), payloads);
    assert!(merged.rewrite && merged.repairs.is_empty());
    std::fs::write(&path, &good[..starts[4] as usize + 5]).unwrap();
    let merged = read_copies(&path, &copy, KIND).unwrap().unwrap();
    assert_eq!(payloads_of(&merged.contents), payloads[..4]);
    assert!(matches!(merged.contents.ending, Ending::Torn { .. }));

    // Different generations (a crash between replacing one and the
    // other): the newer.
    Writer::create(&[&path], KIND, 3, &[b"compacted"]).unwrap();
    std::fs::write(&copy, &good).unwrap();
    let merged = read_copies(&path, &copy, KIND).unwrap().unwrap();
    assert_eq!(merged.contents.generation, 3);
    assert_eq!(payloads_of(&merged.contents), [b"compacted".to_vec()]);
    assert!(merged.rewrite);
    // ... unless it is damaged: then the older, whole.
    let mut newer = std::fs::read(&path).unwrap();
    newer.extend_from_slice(&good[HEADER_LEN..]);
    newer[HEADER_LEN + 2] ^= 1;
    std::fs::write(&path, &newer).unwrap();
    let merged = read_copies(&path, &copy, KIND).unwrap().unwrap();
    assert_eq!(merged.contents.generation, 2);
    assert_eq!(payloads_of(&merged.contents), payloads);

    // A header damaged in one: the other, whole.
    let mut a = good.clone();
    a[20] ^= 1;
    std::fs::write(&path, &a).unwrap();
    std::fs::write(&copy, &good).unwrap();
    let merged = read_copies(&path, &copy, KIND).unwrap().unwrap();
    assert_eq!(payloads_of(&merged.contents), payloads);
    assert_eq!(merged.repairs.len(), 1);
    assert!(merged.rewrite);
    // Neither: nothing.
    std::fs::remove_file(&path).unwrap();
    std::fs::remove_file(&copy).unwrap();
    assert_eq!(read_copies(&path, &copy, KIND).unwrap(), None);
}

#[test]
fn every_single_bit_flip_of_a_log_is_detected() {
    let payloads = sample();
    let bytes = bytes_of(7, &payloads);
    let starts = offsets(&payloads);
    for bit in 0..bytes.len() * 8 {
        let mut flipped = bytes.clone();
        flipped[bit / 8] ^= 1 << (bit % 8);
        match parse(&flipped, KIND, Path::new("x")) {
            Err(_) => assert!(bit / 8 < HEADER_LEN, "bit {bit}"),
            Ok(contents) => {
                let contents = contents.expect("a header");
                let hit = starts.iter().rposition(|&s| s as usize <= bit / 8).unwrap();
                assert_eq!(payloads_of(&contents), payloads[..hit], "bit {bit}");
                assert_ne!(contents.ending, Ending::Clean, "bit {bit}");
            }
        }
    }
}

fn payloads_strategy() -> impl Strategy<Value = Vec<Vec<u8>>> {
    prop::collection::vec(prop::collection::vec(any::<u8>(), 0..200), 0..12)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    /// Any records, any generation: back as written, through a file.
    #[test]
    fn random_records_survive_writing_and_reading(payloads in payloads_strategy(), generation: u64) {
        let scratch = dir("prop-roundtrip");
        let dir = scratch.path();
        let path = dir.join("log");
        let (first, rest) = payloads.split_at(payloads.len() / 2);
        let mut writer = Writer::create(&[&path], KIND, generation, first).unwrap();
        for p in rest {
            writer.append(&[p]).unwrap();
        }
        drop(writer);
        let contents = read(&path, KIND).unwrap().unwrap();
        prop_assert_eq!(contents.generation, generation);
        prop_assert_eq!(&contents.ending, &Ending::Clean);
        prop_assert_eq!(payloads_of(&contents), payloads.clone());
        prop_assert_eq!(std::fs::read(&path).unwrap(), bytes_of(generation, &payloads));
    }

    /// Cut anywhere: the whole records before the cut, and a torn tail
    /// (never damage) unless the cut falls between records.
    #[test]
    fn truncation_at_any_byte_is_a_torn_tail(payloads in payloads_strategy(), cut in any::<prop::sample::Index>()) {
        let bytes = bytes_of(9, &payloads);
        let cut = cut.index(bytes.len() + 1);
        let Some(contents) = parse(&bytes[..cut], KIND, Path::new("x")).unwrap() else {
            prop_assert!(cut < HEADER_LEN);
            return Ok(());
        };
        let kept = payloads_of(&contents);
        prop_assert_eq!(&kept[..], &payloads[..kept.len()]);
        prop_assert!(contents.end() <= cut as u64);
        match contents.ending {
            Ending::Clean => prop_assert_eq!(contents.end(), cut as u64),
            Ending::Torn { at, bytes } => prop_assert_eq!(at + bytes, cut as u64),
            Ending::Damaged(d) => prop_assert!(false, "damage: {}", d),
        }
    }

    /// One bit flipped anywhere: never a record that was not written,
    /// never the one holding the bit, and never a clean ending.
    #[test]
    fn a_flipped_bit_anywhere_is_detected(payloads in payloads_strategy(), bit in any::<prop::sample::Index>()) {
        let bytes = bytes_of(5, &payloads);
        let bit = bit.index(bytes.len() * 8);
        let mut flipped = bytes.clone();
        flipped[bit / 8] ^= 1 << (bit % 8);
        match parse(&flipped, KIND, Path::new("x")) {
            Err(_) => prop_assert!(bit / 8 < HEADER_LEN, "an error past the header"),
            Ok(None) => prop_assert!(false, "a flipped header read as empty"),
            Ok(Some(contents)) => {
                prop_assert!(bit / 8 >= HEADER_LEN);
                let starts = offsets(&payloads);
                let hit = starts.iter().rposition(|&s| s as usize <= bit / 8).unwrap();
                let kept = payloads_of(&contents);
                prop_assert_eq!(&kept[..], &payloads[..hit]);
                prop_assert_ne!(&contents.ending, &Ending::Clean);
                if let Ending::Damaged(d) = &contents.ending {
                    prop_assert_eq!(d.at, starts[hit]);
                    prop_assert_eq!(d.after, payloads.len() - hit - 1);
                }
            }
        }
    }
}

#[test]
#[should_panic(expected = "a journal kind of at most 16 ASCII bytes")]
fn a_kind_too_long_for_the_header_stops_the_write_rather_than_cut_short() {
    crate::header("sensor-copy-epoch", 1);
}
