//! A message that claims absurd sizes (10^9 sets, items, batches, a string
//! of a gigabyte) in a few bytes is refused without allocating for the
//! claim: postcard reads a length prefix and serde reserves at most 1 MiB
//! ahead of a sequence, after which every element needs bytes the message
//! does not have. Measured here with a counting allocator (this test is its
//! own binary, so the allocator sees only it).

use idmesh_protocol::wire::leader_to_leader::{Transfer, WireSet};
use idmesh_protocol::wire::leader_to_sensor::Resent;
use idmesh_protocol::wire::sensor_to_leader::{Batch, Item, Sequenced};
use idmesh_protocol::wire::{decode, encode, WireError, VERSION};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;

static NOW: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let now = NOW.fetch_add(layout.size(), Ordering::SeqCst) + layout.size();
        PEAK.fetch_max(now, Ordering::SeqCst);
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        NOW.fetch_sub(layout.size(), Ordering::SeqCst);
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// postcard's varint for a length prefix.
fn varint(mut n: u64) -> Vec<u8> {
    let mut out = Vec::new();
    loop {
        let byte = (n & 0x7f) as u8;
        n >>= 7;
        if n == 0 {
            out.push(byte);
            return out;
        }
        out.push(byte | 0x80);
    }
}

/// One measurement at a time: the counters are the process's.
static MEASURING: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// The bytes allocated at the peak while `f` ran, above what was live
/// before.
fn peak_during<T>(f: impl FnOnce() -> T) -> (T, usize) {
    let _one = MEASURING.lock().unwrap_or_else(|e| e.into_inner());
    let before = NOW.load(Ordering::SeqCst);
    PEAK.store(before, Ordering::SeqCst);
    let out = f();
    (out, PEAK.load(Ordering::SeqCst).saturating_sub(before))
}

const BILLION: u64 = 1_000_000_000;
/// Far less than any claim below would need, more than serde's 1 MiB.
const LIMIT: usize = 4 << 20;

fn assert_refused_cheaply<T: std::fmt::Debug>(
    what: &str,
    decoded: impl FnOnce() -> Result<T, WireError>,
) {
    let (result, peak) = peak_during(decoded);
    assert!(
        matches!(result, Err(WireError::Decode { .. })),
        "{what}: {result:?}"
    );
    assert!(peak < LIMIT, "{what}: {peak} bytes allocated");
    eprintln!("{what}: refused, {peak} bytes at the peak");
}

#[test]
fn a_billion_of_anything_in_a_few_bytes_is_refused_without_allocating_for_it() {
    // A batch header, then a claim of 10^9 items and one real item.
    let one_item = encode(&Sequenced {
        seq: 1,
        item: Item::Cut {
            events: 0,
            tag: 1,
            rows: false,
        },
    });
    let mut batch = encode(&(VERSION, "sensor-0", 3u64, 9u64, 9u64, false));
    batch.extend(varint(BILLION));
    batch.extend(&one_item);
    assert_refused_cheaply("batch of 10^9 items", || decode::<Batch>(&batch));

    // A transfer claiming 10^9 sets, with a thousand real ones.
    let set = encode(&WireSet {
        red: vec![1, 2],
        blue: vec![3],
        ln_mass: -1.0,
    });
    let mut transfer = encode(&(VERSION, 1u16, 7u64));
    transfer.extend(varint(BILLION));
    for _ in 0..1000 {
        transfer.extend(&set);
    }
    assert_refused_cheaply("transfer of 10^9 sets", || decode::<Transfer>(&transfer));

    // A set claiming 10^9 red tracks.
    let mut huge_set = encode(&(VERSION, 1u16, 7u64));
    huge_set.extend(varint(1));
    huge_set.extend(varint(BILLION));
    huge_set.extend([1, 2, 3]);
    assert_refused_cheaply("set of 10^9 tracks", || decode::<Transfer>(&huge_set));

    // A resend reply claiming 10^9 batches.
    let mut resent = encode(&VERSION);
    resent.extend(varint(BILLION));
    assert_refused_cheaply("10^9 batches", || decode::<Resent>(&resent));

    // A sensor name of a gigabyte, and of u64::MAX bytes.
    for claim in [BILLION, u64::MAX] {
        let mut name = encode(&VERSION);
        name.extend(varint(claim));
        name.extend(b"sensor");
        assert_refused_cheaply("a huge string", || decode::<Batch>(&name));
    }
}

/// The same claims, honest in their prefix but with the body cut short at
/// every point, never panic and never allocate much.
#[test]
fn every_truncation_of_a_large_message_is_refused() {
    let transfer = Transfer {
        trees: Vec::new(),
        components: Vec::new(),
        version: VERSION,
        from: 1,
        seq: 7,
        sets: (0..2000)
            .map(|i| WireSet {
                red: vec![i, i + 1],
                blue: vec![i + 2],
                ln_mass: -(i as f64),
            })
            .collect(),
        rows: vec![],
    };
    let bytes = encode(&transfer);
    assert_eq!(decode::<Transfer>(&bytes).unwrap(), transfer);
    for cut in (0..bytes.len()).step_by(97) {
        let (result, peak) = peak_during(|| decode::<Transfer>(&bytes[..cut]));
        assert!(result.is_err(), "cut at {cut} of {}", bytes.len());
        assert!(peak < LIMIT, "cut at {cut}: {peak} bytes");
    }
}
