//! Property test: damaged copies of a real short run's traces (`launch/report/testdata/short-run`, see its
//! README) — truncated, with bits flipped, bytes set to the markers of long lengths, bytes
//! inserted or deleted, anywhere, at the start of the header or at a frame's length. The readers
//! of `report` (the join), `trace export` (CSV and MCAP) and `run --replay` (its recording check) never panic,
//! never allocate more than a bound, and for every damaged file give an error (or, for the join,
//! a warning) that names the file and the byte offset.
//!
//! Allocations are counted by a test-only global allocator that passes every call to the system
//! allocator and keeps, per thread, the largest single request and the peak of live bytes.
#![allow(unsafe_code)]

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::path::{Path, PathBuf};

use fdi_common::run_dir::RunDir;
use fdi_common::scenario::{self, Resolved};
use fdi_common::trace::{TraceError, TraceReader};
use proptest::prelude::*;
use proptest::sample::Index;

use crate::run::replayer;
use fdi_report::{export, join};

/// Largest single allocation any reader may make: the readers' 64 KiB buffers, with room to
/// spare; a damaged length used to ask for up to 8e18 bytes.
const MAX_ONE_ALLOCATION: usize = 1 << 20;
/// Largest growth of live heap bytes while a reader runs (an undamaged run needs well under
/// a tenth of it).
const MAX_LIVE_GROWTH: usize = 32 << 20;

thread_local! {
    static LARGEST: Cell<usize> = const { Cell::new(0) };
    static LIVE: Cell<isize> = const { Cell::new(0) };
    static PEAK: Cell<isize> = const { Cell::new(0) };
}

fn note_alloc(size: usize) {
    let _ = LARGEST.try_with(|l| l.set(l.get().max(size)));
    let _ = LIVE.try_with(|l| {
        let v = l.get().saturating_add(size as isize);
        l.set(v);
        let _ = PEAK.try_with(|p| p.set(p.get().max(v)));
    });
}

fn note_free(size: usize) {
    let _ = LIVE.try_with(|l| l.set(l.get().saturating_sub(size as isize)));
}

/// Counts allocations on the way to the system allocator.
struct Counting;

// SAFETY: every call goes to `System` unchanged, with the caller's arguments; the bookkeeping
// only touches thread-local `Cell`s with constant initializers, which never allocate.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note_alloc(layout.size());
        // SAFETY: the caller's contract is passed on unchanged.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note_alloc(layout.size());
        // SAFETY: as above.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        note_free(layout.size());
        // SAFETY: as above.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note_free(layout.size());
        note_alloc(new_size);
        // SAFETY: as above.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// `f`'s result, the largest single allocation on this thread while it ran, and the peak
/// growth of this thread's live heap bytes.
fn measured<R>(f: impl FnOnce() -> R) -> (R, usize, usize) {
    LARGEST.with(|l| l.set(0));
    let base = LIVE.with(Cell::get);
    PEAK.with(|p| p.set(base));
    let r = f();
    let largest = LARGEST.with(Cell::get);
    let growth = (PEAK.with(Cell::get) - base).max(0) as usize;
    (r, largest, growth)
}

fn fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../report/testdata/short-run")
}

/// The fixture's trace files, sorted.
fn fixture_traces() -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> =
        std::fs::read_dir(fdi_common::run_dir::RunDir::new(fixture()).traces())
            .expect("the fixture's traces")
            .flatten()
            .map(|e| e.path())
            .filter(|p| p.extension().is_some_and(|x| x == "trace"))
            .collect();
    v.sort();
    v
}

/// The recorded scenario: the paper's, 20 ticks (built here rather than read from the fixture,
/// so that the test does not depend on the scenario file format).
fn resolved() -> Resolved {
    let mut r = scenario::paper().expect("the paper scenario");
    r.scenario.duration_s = 0.02;
    r
}

/// A copy of the fixture run directory.
fn copy_fixture() -> tempfile::TempDir {
    let tmp = tempfile::tempdir().expect("a scratch folder");
    std::fs::create_dir(fdi_common::run_dir::RunDir::new(tmp.path()).traces()).expect("traces/");
    std::fs::copy(
        fdi_common::run_dir::RunDir::new(fixture()).scenario(),
        fdi_common::run_dir::RunDir::new(tmp.path()).scenario(),
    )
    .expect("copy");
    for t in fixture_traces() {
        let to = fdi_common::run_dir::RunDir::new(tmp.path())
            .traces()
            .join(t.file_name().expect("name"));
        std::fs::copy(&t, to).expect("copy");
    }
    tmp
}

/// Offsets of every frame (its length field) of an undamaged trace, the header's first.
fn frame_starts(bytes: &[u8]) -> Vec<usize> {
    let mut out = Vec::new();
    let mut at = 12;
    while at + 4 <= bytes.len() {
        out.push(at);
        let len = u32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]]);
        at += 4 + len as usize;
    }
    out
}

/// Where a mutation applies.
#[derive(Debug, Clone)]
enum Spot {
    /// Anywhere in the file.
    Anywhere(Index),
    /// Within the first 48 bytes: magic, version, header length, the header's first strings.
    HeaderStart(u8),
    /// At or just after the start of a frame (its length and first bytes).
    Frame(Index, u8),
    /// The varint length of the header's first string (`process`, at byte 17) or its second
    /// (`scenario_toml`, right after the first).
    HeaderString(bool),
}

impl Spot {
    fn offset(&self, bytes: &[u8], frames: &[usize]) -> usize {
        let len = bytes.len().max(1);
        let at = match self {
            Self::Anywhere(i) => i.index(len),
            Self::HeaderStart(d) => usize::from(*d % 48),
            Self::Frame(i, d) => frames
                .get(i.index(frames.len().max(1)))
                .map_or(0, |f| f + usize::from(*d % 8)),
            Self::HeaderString(false) => 17,
            Self::HeaderString(true) => 18 + bytes.get(17).map_or(0, |n| usize::from(*n)),
        };
        at.min(bytes.len())
    }
}

#[derive(Debug, Clone)]
enum Mutation {
    Truncate(Spot),
    FlipBit(Spot, u8),
    SetByte(Spot, u8),
    Insert(Spot, Vec<u8>),
    Delete(Spot, u8),
}

fn spot() -> impl Strategy<Value = Spot> {
    prop_oneof![
        any::<Index>().prop_map(Spot::Anywhere),
        any::<u8>().prop_map(Spot::HeaderStart),
        (any::<Index>(), any::<u8>()).prop_map(|(i, d)| Spot::Frame(i, d)),
    ]
}

fn mutation() -> impl Strategy<Value = Mutation> {
    // Varint markers of a u16, u32, u64 or u128 length follow; 0x00 and 0x80 as well.
    let byte = prop_oneof![
        prop::sample::select(vec![0xfb_u8, 0xfc, 0xfd, 0xfe, 0xff, 0x00, 0x80]),
        any::<u8>(),
    ];
    prop_oneof![
        spot().prop_map(Mutation::Truncate),
        (spot(), 0..8_u8).prop_map(|(s, b)| Mutation::FlipBit(s, b)),
        (spot(), byte).prop_map(|(s, b)| Mutation::SetByte(s, b)),
        (spot(), prop::collection::vec(any::<u8>(), 1..16))
            .prop_map(|(s, v)| Mutation::Insert(s, v)),
        (spot(), 1..16_u8).prop_map(|(s, n)| Mutation::Delete(s, n)),
        // A string length turned into "a u16, u32 or u64 length follows".
        (
            any::<bool>(),
            prop::sample::select(vec![0xfb_u8, 0xfc, 0xfd])
        )
            .prop_map(|(second, b)| Mutation::SetByte(Spot::HeaderString(second), b)),
    ]
}

fn apply(bytes: &mut Vec<u8>, m: &Mutation) {
    let frames = frame_starts(bytes);
    match m {
        Mutation::Truncate(s) => {
            let at = s.offset(bytes, &frames);
            bytes.truncate(at);
        }
        Mutation::FlipBit(s, b) => {
            let at = s.offset(bytes, &frames).min(bytes.len().saturating_sub(1));
            if let Some(x) = bytes.get_mut(at) {
                *x ^= 1 << (b % 8);
            }
        }
        Mutation::SetByte(s, v) => {
            let at = s.offset(bytes, &frames).min(bytes.len().saturating_sub(1));
            if let Some(x) = bytes.get_mut(at) {
                *x = *v;
            }
        }
        Mutation::Insert(s, v) => {
            let at = s.offset(bytes, &frames);
            bytes.splice(at..at, v.iter().copied());
        }
        Mutation::Delete(s, n) => {
            let at = s.offset(bytes, &frames);
            let end = (at + usize::from(*n)).min(bytes.len());
            bytes.drain(at..end);
        }
    }
}

/// The error that ends reading `path` whole, if any.
fn first_damage(path: &Path) -> Option<TraceError> {
    let reader = match TraceReader::open(path) {
        Ok(r) => r,
        Err(e) => return Some(e),
    };
    reader.into_iter().find_map(Result::err)
}

fn names_file_and_offset(text: &str, path: &Path) -> bool {
    text.lines()
        .any(|l| l.contains(&path.display().to_string()) && l.contains("byte offset"))
}

#[test]
fn the_short_run_fixture_reads_whole_and_joins_every_tick() {
    for t in fixture_traces() {
        assert!(
            first_damage(&t).is_none(),
            "{} no longer reads whole: make launch/report/testdata/short-run again (see its README)",
            t.display()
        );
    }
    let dir = copy_fixture();
    let joined =
        join::join_run(&resolved(), &RunDir::new(dir.path()), 0.0, |_| {}).expect("joined");
    assert_eq!(joined.summary.ticks, 20, "{:?}", joined.warnings);
    assert!(joined.warnings.is_empty(), "{:?}", joined.warnings);
    export::export(&RunDir::new(dir.path()), export::Format::Csv, &mut |_| {}).expect("exported");
    export::export(&RunDir::new(dir.path()), export::Format::Mcap, &mut |_| {}).expect("exported");
    replayer::check_recording(&resolved(), &RunDir::new(dir.path())).expect("replayable");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    #[test]
    fn damaged_traces_never_panic_or_overallocate_and_name_file_and_offset(
        file in any::<Index>(),
        m in mutation(),
    ) {
        let dir = copy_fixture();
        let traces = fixture_traces();
        let name = traces[file.index(traces.len())].file_name().expect("name").to_owned();
        let path = RunDir::new(dir.path()).traces().join(&name);
        let mut bytes = std::fs::read(&path).expect("read");
        apply(&mut bytes, &m);
        std::fs::write(&path, &bytes).expect("write");
        let r = resolved();

        let (damage, big, grew) = measured(|| first_damage(&path));
        prop_assert!(big <= MAX_ONE_ALLOCATION && grew <= MAX_LIVE_GROWTH, "reader: {big} / {grew} bytes");
        if let Some(d) = &damage {
            prop_assert!(d.offset().is_some() && names_file_and_offset(&d.to_string(), &path), "{d}");
        }

        let (joined, big, grew) = measured(|| join::join_run(&r, &RunDir::new(dir.path()), 0.0, |_| {}));
        prop_assert!(big <= MAX_ONE_ALLOCATION && grew <= MAX_LIVE_GROWTH, "report's join: {big} / {grew} bytes");
        let text = match &joined {
            Ok(j) => j.warnings.join("\n"),
            Err(e) => format!("{e:#}"),
        };
        if damage.is_some() {
            prop_assert!(names_file_and_offset(&text, &path), "report's join: {text}");
        }

        for format in [export::Format::Csv, export::Format::Mcap] {
            let (exported, big, grew) = measured(|| export::export(&RunDir::new(dir.path()), format, &mut |_| {}));
            prop_assert!(big <= MAX_ONE_ALLOCATION && grew <= MAX_LIVE_GROWTH, "export {format:?}: {big} / {grew} bytes");
            if damage.is_some() {
                let text = exported.as_ref().err().map(|e| format!("{e:#}")).unwrap_or_default();
                prop_assert!(names_file_and_offset(&text, &path), "export {format:?}: {text}");
            }
        }

        // The replay reads the attacker trace and checks the agents'; the center's is re-made.
        if name != "control-center.trace" {
            let (checked, big, grew) = measured(|| replayer::check_recording(&r, &RunDir::new(dir.path())));
            prop_assert!(big <= MAX_ONE_ALLOCATION && grew <= MAX_LIVE_GROWTH, "replay check: {big} / {grew} bytes");
            if damage.is_some() {
                let text = checked.as_ref().err().map(|e| format!("{e:#}")).unwrap_or_default();
                prop_assert!(names_file_and_offset(&text, &path), "replay check: {text}");
            }
        }
    }
}
