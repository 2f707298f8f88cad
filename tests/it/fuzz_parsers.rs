//! Every parser of outside input never panics: the configuration loader, recipes and limit
//! callouts, the SJ-210 codec and reply parsers, the GRBL and Zaber reply parsers and line
//! framer, grid and profile CSV, recorded transcripts, journal records, the control protocol,
//! the IGES reader and the X3P reader are fed mutated copies of valid input (bit flips, cut and repeated spans, and
//! tokens that break parsers: huge and negative numbers, NaN, separators, line ends, non-ASCII)
//! and plain random bytes. A panic fails the case, and proptest shrinks it to a small input.
//!
//! CI runs 3000 cases per parser (about 8 s in all on 2 cores). A long run, e.g. overnight
//! (a million cases per parser, roughly an hour on 2 cores):
//!
//! ```text
//! SURFSCAN_FUZZ_CASES=1000000 cargo test --test it fuzz_parsers:: -- --test-threads=2
//! ```
//!
//! in the default (debug) profile on purpose: its overflow checks turn a wrapping size
//! computation into a panic that is found, where `--release` would let it wrap silently.
//!
//! (`cargo fuzz` needs nightly Rust, which the stations' toolchains are not.) Each panic found
//! is pinned by a regression test named after its case at the end of this module.

use proptest::collection::vec;
use proptest::prelude::*;
use proptest::test_runner::{Config, TestRunner};
use std::path::Path;

/// Cases per parser: `SURFSCAN_FUZZ_CASES`, or `ci` when unset.
fn cases(ci: u32) -> u32 {
    std::env::var("SURFSCAN_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(ci)
}

/// Runs `check` on `cases(ci)` inputs drawn from `strategy`; a panic is a failure, shrunk.
fn fuzz<S: Strategy>(ci: u32, strategy: S, check: impl Fn(S::Value))
where
    S::Value: std::fmt::Debug,
{
    let config = Config {
        cases: cases(ci),
        // Failures become named regression tests, not files written into the source tree.
        failure_persistence: None,
        ..Config::default()
    };
    let mut runner = TestRunner::new(config);
    if let Err(e) = runner.run(&strategy, |v| {
        check(v);
        Ok(())
    }) {
        panic!("{e}");
    }
}

/// Tokens that tend to break parsers, spliced into otherwise valid input.
const TOKENS: &[&[u8]] = &[
    b"0",
    b"-0",
    b"-1",
    b"1e-30",
    b"1e308",
    b"1e309",
    b"-1e309",
    b"NaN",
    b"nan",
    b"inf",
    b"-inf",
    b"4294967295",
    b"4294967296",
    b"18446744073709551615",
    b"18446744073709551616",
    b"9223372036854775807",
    b"-9223372036854775808",
    b"99999999999999999999",
    b"65536",
    b"256",
    b"000",
    b"0.0",
    b".",
    b",",
    b";",
    b":",
    b"=",
    b"\"",
    b"{",
    b"}",
    b"[",
    b"]",
    b"<",
    b">",
    b"|",
    b"\\",
    b"\r",
    b"\n",
    b"\r\n",
    b" ",
    b"\t",
    b"\0",
    b"\xff",
    b"\xc3\xa9",
    b"\xc2\xb5",
    b"\xf4\x8f\xbf\xbf",
    b"\xe2\x80\xae",
];

/// One edit of a seed. Positions are taken modulo the current length.
#[derive(Debug, Clone)]
enum Edit {
    /// XOR one byte.
    Flip(usize, u8),
    /// Insert bytes.
    Insert(usize, Vec<u8>),
    /// Insert one of [`TOKENS`] or the parser's own.
    Token(usize, usize),
    /// Overwrite with a token, keeping the length (fixed-column formats stay aligned).
    Overwrite(usize, usize),
    /// Delete a span.
    Delete(usize, usize),
    /// Repeat a span in place.
    Repeat(usize, usize, u8),
    /// Cut everything from here.
    Truncate(usize),
    /// Replace the n-th number in the input with one of [`NUMBERS`].
    Number(usize, usize),
}

/// Numbers at the edges of what parsers and the arithmetic after them handle.
const NUMBERS: &[&[u8]] = &[
    b"0",
    b"-1",
    b"1e-30",
    b"-1e-30",
    b"1e308",
    b"-1e308",
    b"1e309",
    b"NaN",
    b"inf",
    b"255",
    b"256",
    b"65535",
    b"65536",
    b"2147483648",
    b"4294967295",
    b"4294967296",
    b"9223372036854775807",
    b"9223372036854775808",
    b"18446744073709551615",
    b"18446744073709551616",
    b"-9223372036854775808",
    b"0.000000000000000000001",
    b"99999999999999999999999999",
];

fn edit() -> impl Strategy<Value = Edit> {
    prop_oneof![
        1 => (any::<usize>(), 1..=255u8).prop_map(|(p, x)| Edit::Flip(p, x)),
        1 => (any::<usize>(), vec(any::<u8>(), 1..8)).prop_map(|(p, b)| Edit::Insert(p, b)),
        2 => (any::<usize>(), any::<usize>()).prop_map(|(p, t)| Edit::Token(p, t)),
        1 => (any::<usize>(), any::<usize>()).prop_map(|(p, t)| Edit::Overwrite(p, t)),
        1 => (any::<usize>(), 1..64usize).prop_map(|(p, n)| Edit::Delete(p, n)),
        3 => (any::<usize>(), any::<usize>()).prop_map(|(k, t)| Edit::Number(k, t)),
        1 => (any::<usize>(), 1..64usize, 1..8u8).prop_map(|(p, n, k)| Edit::Repeat(p, n, k)),
        1 => any::<usize>().prop_map(Edit::Truncate),
    ]
}

fn apply(seed: &[u8], edits: &[Edit], extra: &[&[u8]]) -> Vec<u8> {
    let mut b = seed.to_vec();
    let token = |t: usize| -> &[u8] {
        let all = TOKENS.len() + extra.len();
        let t = t % all;
        if t < TOKENS.len() {
            TOKENS[t]
        } else {
            extra[t - TOKENS.len()]
        }
    };
    for e in edits {
        let at = |p: usize, len: usize| if len == 0 { 0 } else { p % (len + 1) };
        match e {
            Edit::Flip(p, x) if !b.is_empty() => {
                let i = p % b.len();
                b[i] ^= x;
            }
            Edit::Flip(..) => {}
            Edit::Insert(p, bytes) => {
                let i = at(*p, b.len());
                b.splice(i..i, bytes.iter().copied());
            }
            Edit::Token(p, t) => {
                let i = at(*p, b.len());
                b.splice(i..i, token(*t).iter().copied());
            }
            Edit::Overwrite(p, t) => {
                let tok = token(*t);
                if b.len() >= tok.len() {
                    let i = p % (b.len() - tok.len() + 1);
                    b[i..i + tok.len()].copy_from_slice(tok);
                }
            }
            Edit::Delete(p, n) => {
                let i = at(*p, b.len());
                let end = (i + n).min(b.len());
                b.drain(i..end);
            }
            Edit::Repeat(p, n, k) => {
                let i = at(*p, b.len());
                let end = (i + n).min(b.len());
                let span = b[i..end].to_vec();
                for _ in 0..*k {
                    b.splice(end..end, span.iter().copied());
                }
            }
            Edit::Truncate(p) => {
                let i = at(*p, b.len());
                b.truncate(i);
            }
            Edit::Number(k, t) => {
                let spans = number_spans(&b);
                if !spans.is_empty() {
                    let (i, end) = spans[k % spans.len()];
                    b.splice(i..end, NUMBERS[t % NUMBERS.len()].iter().copied());
                }
            }
        }
    }
    b
}

/// Where the numbers are: runs of digits with their sign, point and exponent.
fn number_spans(b: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        if b[i].is_ascii_digit() {
            let start = if i > 0 && b[i - 1] == b'-' { i - 1 } else { i };
            let mut end = i;
            while end < b.len()
                && (b[end].is_ascii_digit()
                    || matches!(b[end], b'.' | b'e' | b'E' | b'+' | b'-' | b'D'))
            {
                end += 1;
            }
            out.push((start, end));
            i = end;
        } else {
            i += 1;
        }
    }
    out
}

/// One generated input; shown as an escaped byte string when a case fails, so the failing
/// input can be pasted into a regression test.
#[derive(Clone)]
struct Input(Vec<u8>);

impl std::fmt::Debug for Input {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "b\"{}\"", self.0.escape_ascii())
    }
}

impl std::ops::Deref for Input {
    type Target = [u8];
    fn deref(&self) -> &[u8] {
        &self.0
    }
}

/// Mutated seeds (most cases) and random bytes.
fn inputs(seeds: Vec<Vec<u8>>, extra: &'static [&'static [u8]]) -> BoxedStrategy<Input> {
    let n = seeds.len();
    prop_oneof![
        6 => (0..n, vec(edit(), 1..6)).prop_map(move |(s, e)| Input(apply(&seeds[s], &e, extra))),
        1 => vec(any::<u8>(), 0..512).prop_map(Input),
    ]
    .boxed()
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

// --- configuration -------------------------------------------------------------------

fn config_seeds() -> Vec<Vec<u8>> {
    let shipped =
        std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/config/surfscan.toml")).unwrap();
    let zaber = br#"[instrument]
port = "/dev/sj210"
pitch-x-um = 0.5
[instrument.timeouts]
trace-deadline-ms = 60000
[stage]
port = "/dev/ystage"
protocol = "zaber"
nm-per-microstep = 47.625
allow-inexact-step = true
device = 1
axis = 1
soft-limit-min-mm = 0.0
soft-limit-max-mm = 50.0
[scan]
lines = 8
y-start-mm = 1.0
y-step-mm = 0.01
[fit]
degree-u = 3
degree-v = 3
[analysis]
lambda-c-mm = 0.8
[output]
dir = "/tmp/scans"
[notify]
command = ["/bin/true"]
timeout-s = 5
"#;
    vec![shipped, zaber.to_vec()]
}

#[test]
fn config_loader() {
    const EXTRA: &[&[u8]] = &[
        b" = 0\n",
        b" = -1\n",
        b" = 1e-30\n",
        b" = 1e300\n",
        b" = nan\n",
    ];
    fuzz(3000, inputs(config_seeds(), EXTRA), |b| {
        // What start-up does with a file: parse, validate, then derive every driver's
        // settings and the plan from it.
        if let Ok(c) = surfscan::config::Config::parse(Path::new("fuzz.toml"), &text(&b)) {
            let _ = surfscan::cli::station::plan_of(&c);
            let _ = c.y_grid_nm();
            let _ = c.fit.v_method_for(c.scan.lines as usize);
            let _ = c.analysis.spike_options();
            let _ = c.stage.policy_config();
            let _ = c.stage.nm_per_unit();
            let _ = c.instrument.client_options();
            let _ = c.instrument.validate();
        }
    });
}

// --- recipes and callouts -------------------------------------------------------------

#[test]
fn recipe_loader_and_callouts() {
    const RECIPE: &[u8] = br#"description = "brass"
[plan]
lines = 8
y-start-mm = 2.0
y-step-mm = 0.01
[conditions]
lambda-c-mm = 0.8
lambda-s-um = 2.5
sampling-lengths = 5
speed-mm-s = 0.5
[analysis]
outliers = "exclude"
[specification]
limits = ["Ra 0.8", "Rz max 6.3", "L Ra 0.2", "0.0025-0.8/Rz5 3.2", "U RSm 200 um"]
[queue]
stop-on-failure = true
"#;
    const EXTRA: &[&[u8]] = &[
        b"Ra0.8x",
        b" max ",
        b"/",
        b"-",
        b"\"U ",
        b"\"L ",
        b"Rz1max",
        b"0,8",
        b" mm",
        b"\xc2\xb5",
        b" = nan\n",
        b" = 1e300\n",
        b"99999999999999999999",
    ];
    let station = surfscan::config::Config::parse(
        Path::new("station.toml"),
        std::str::from_utf8(&config_seeds()[1]).unwrap(),
    )
    .unwrap();
    fuzz(3000, inputs(vec![RECIPE.to_vec()], EXTRA), |b| {
        let text = text(&b);
        // What a start does with a recipe: parse and validate it, then its configuration.
        if let Ok(r) = surfscan::jobs::recipe::Recipe::from_text(
            "fuzz",
            Path::new("fuzz.toml"),
            &text,
            &station,
        ) {
            let _ = r.config_for(&station, Some(3.0));
            let _ = r.summary(&station);
        }
        // Each line as a callout on its own.
        for line in text.lines() {
            let _ = line.parse::<surfscan::specification::Callout>();
        }
    });
}

// --- SJ-210 --------------------------------------------------------------------------

const SJ210_REPLIES: &[&[u8]] = &[
    b"OK\r",
    b"NG011\r",
    b"NG030,12\r",
    b"OK000\r",
    b"OK3120504.0012\r",
    b"OK0302232050.500220.0030.019\r",
    b"OK05    0.123   -0.456    1.789    0.000   -2.500\r",
    b"OK3,0.1,-0.2,0.3\r",
    b"OKRa      1.234 um\r",
    b"OK00812\r",
    b"OK0.0\r",
    b"\x00\x00OK\r\nNG101\r",
];

#[test]
fn sj210_codec_and_reply_parsers() {
    use bytes::BytesMut;
    use surfscan::sj210::codec::{classify, encode_command, Reply, Sj210Codec};
    use surfscan::sj210::models::{ModelId, ModelTable};
    use surfscan::sj210::replies::{
        battery_from_code, leading_number, parse_block, parse_code, parse_param_count, parse_result,
    };
    use tokio_util::codec::Decoder;

    let seeds: Vec<Vec<u8>> = SJ210_REPLIES.iter().map(|s| s.to_vec()).collect();
    let tables: Vec<ModelTable> = [
        ModelId::Sj210,
        ModelId::Sj220,
        ModelId::Sj310,
        ModelId::Sj410,
    ]
    .into_iter()
    .map(ModelTable::builtin)
    .collect();
    const EXTRA: &[&[u8]] = &[b"OK", b"NG", b"RDEVA", b"       "];
    let strategy = (inputs(seeds, EXTRA), vec(1..64usize, 1..8), 0..16usize);
    fuzz(3000, strategy, |(b, chunks, width)| {
        // The codec over the bytes in arbitrary chunks, as reads deliver them.
        let mut codec = Sj210Codec::new(64);
        let mut buf = BytesMut::new();
        let mut rest = &b[..];
        let mut lines = Vec::new();
        for n in chunks.iter().cycle() {
            if rest.is_empty() {
                break;
            }
            let (now, later) = rest.split_at((*n).min(rest.len()));
            buf.extend_from_slice(now);
            rest = later;
            while let Ok(Some(line)) = codec.decode(&mut buf) {
                lines.push(line);
            }
        }
        while let Ok(Some(line)) = codec.decode_eof(&mut buf) {
            lines.push(line);
        }
        let _ = encode_command(&text(&b));
        lines.push(classify(&b));
        for reply in lines {
            let payload = match reply {
                Reply::Ok(p) => p,
                Reply::Malformed(raw) => text(&raw),
                Reply::Ng { code, .. } => code.code().to_string(),
            };
            let _ = parse_block(&payload);
            let _ = parse_result("RDRES02", &payload, width);
            let _ = parse_code(&payload).map(battery_from_code);
            let _ = leading_number(&payload);
            let _ = parse_param_count(&payload);
            for t in &tables {
                let _ = t.parse_conditions(&payload);
            }
        }
    });
}

// --- stages --------------------------------------------------------------------------

const GRBL_LINES: &[&[u8]] = &[
    b"ok",
    b"error:9",
    b"ALARM:2",
    b"<Idle|MPos:0.000,-20.000,0.000|FS:0,0>",
    b"<Jog|WPos:1.000,2.000,3.000|Bf:15,128|FS:60,0|WCO:0.000,-1.000,0.000>",
    b"<Hold:0|MPos:0.000,0.000,0.000|Pn:XYZ>",
    b"[MSG:Reset to continue]",
    b"[MSG:'$H'|'$X' to unlock]",
    b"Grbl 1.1h ['$' for help]",
    b"[VER:1.1h.20190825:station-7]",
    b"[OPT:V,15,128]",
    b"$101=400.000",
    b">G54G17:ok",
];

const ZABER_LINES: &[&[u8]] = &[
    b"@01 1 OK IDLE -- 0",
    b"@01 0 OK BUSY -- 12345",
    b"@01 1 00 OK IDLE -- 36283",
    b"@01 1 12 RJ IDLE -- BADCOMMAND",
    b"@01 1 OK IDLE WR 0",
    b"@01 1 OK IDLE FS 0:5B",
    b"#01 1 info line\\",
    b"#01 1 continued",
    b"!01 1 IDLE --",
    b"@01 1 OK IDLE NI 0\\",
];

#[test]
fn grbl_and_zaber_reply_parsers_and_line_framer() {
    use surfscan::stage::framer::LineFramer;
    let seeds: Vec<Vec<u8>> = GRBL_LINES
        .iter()
        .chain(ZABER_LINES)
        .map(|s| s.to_vec())
        .collect();
    const EXTRA: &[&[u8]] = &[b"MPos:", b"WCO:", b"|", b"@01", b" -- ", b"OK", b"RJ"];
    fuzz(
        3000,
        (inputs(seeds, EXTRA), vec(1..32usize, 1..6)),
        |(b, chunks)| {
            let line = text(&b);
            let _ = surfscan::stage::grbl::codec::parse_line(&line);
            let _ = surfscan::stage::zaber::codec::parse_line(&line);
            let mut framer = LineFramer::new(48);
            let mut rest = &b[..];
            for n in chunks.iter().cycle() {
                if rest.is_empty() {
                    break;
                }
                let (now, later) = rest.split_at((*n).min(rest.len()));
                rest = later;
                for l in framer.push(now).into_iter().flatten() {
                    let _ = surfscan::stage::grbl::codec::parse_line(&l);
                    let _ = surfscan::stage::zaber::codec::parse_line(&l);
                }
            }
        },
    );
}

// --- CSV -----------------------------------------------------------------------------

#[test]
fn grid_and_profile_csv() {
    let real = |name: &str| {
        let path = format!("{}/tests/data/{name}", env!("CARGO_MANIFEST_DIR"));
        let t = std::fs::read(path).unwrap();
        // A few rows are enough to reach every branch; whole files only slow the cases.
        let cut = t
            .iter()
            .enumerate()
            .filter(|(_, &c)| c == b'\n')
            .nth(5)
            .map_or(t.len(), |(i, _)| i + 1);
        t[..cut].to_vec()
    };
    let seeds = vec![
        b"x_mm,z_um\n0,0.1\n0.0015,-0.2\n0.003,0.3\n".to_vec(),
        b"0.1,0.2,0.3\n-1,2e-3,4\n\n".to_vec(),
        b"y_mm,x_mm,z_um\n0,0,0.1\n0,0.5,0.2\n0.01,0,0.3\n0.01,0.5,0.4\n".to_vec(),
        real("sur-2.grid.csv"),
    ];
    const EXTRA: &[&[u8]] = &[b"x_mm,z_um\n", b"y_mm,x_mm,z_um\n", b",\n"];
    fuzz(3000, (inputs(seeds, EXTRA), 0..4u8), |(b, pitch)| {
        let t = text(&b);
        let pitch_mm = [0.0015, 0.0, -1.0, f64::NAN][pitch as usize];
        let grid_csv = surfscan::input::ReadOptions {
            pitch_x_mm: Some(0.0015),
            pitch_y_mm: Some(0.01),
            z_unit: None,
        };
        let _ = surfscan::input::read_csv(Path::new("fuzz.csv"), b.to_vec(), &grid_csv);
        let _ = surfscan::scan::line_csv::parse_csv(Path::new("fuzz.csv"), &t, pitch_mm);
        // The simulator's own reader of the traces it serves.
        let _ = surfscan_sim::ProfileSet::parse(&t, Some(pitch_mm));
        let _ = surfscan_sim::ProfileSet::parse(&t, None);
    });
}

// --- transcripts ---------------------------------------------------------------------

#[test]
fn transcripts() {
    use std::time::Duration;
    use surfscan_sim::replay::{Replay, Transcript};
    let seed = b"# surfscan transcript v1\n# instrument: SJ-210\n# firmware: 1.23\n\
0.000000 > RDSTU00\\r\n0.012000 < OK0\\r\n0.100000 > CTSTA\\r\n0.150000 < OK\\r\n\
0.400000 > RDSTU00\\r\n0.410000 < OK1\\r\n2.000000 > RDSTU00\\r\n2.010000 < OK0\\r\n\
2.100000 > RDEVA00\\r\n2.200000 < OK00003\\r\n2.300000 > RDEVA03\\r\n2.400000 < OK3,0.1,\\x2d0.2,0.3\\r\\n\n"
        .to_vec();
    const EXTRA: &[&[u8]] = &[b"\\x", b"\\xZZ", b"\\", b" > ", b" < ", b"\n# k: v\n"];
    fuzz(
        3000,
        (inputs(vec![seed], EXTRA), vec(0..5000u64, 1..6), 0..3u8),
        |(b, times_ms, scale)| {
            let Ok(t) = Transcript::parse(&text(&b)) else {
                return;
            };
            let mut r = Replay::new(&t, [1.0, 0.0, 1e-300][scale as usize]);
            for (e, ms) in t.entries.iter().zip(times_ms.iter().cycle()) {
                let _ = r.respond(&e.bytes, Duration::from_millis(*ms));
            }
        },
    );
}

// --- journal -------------------------------------------------------------------------

#[test]
fn journal_records() {
    use surfscan::scan::journal::{parse_journal, ResumeState};
    let seed = br#"{"class":"start","scan_id":"20260101T000000Z-A17","time":"2026-01-01T00:00:00Z","plan":{"lines":8},"config":{},"config_hash":"ab","specimen":"A17","operator":"R","notes":"","software_version":"0.1.0","instrument_model":"SJ-210","firmware":"1.0","drive_unit":"standard","conditions":{"standard":"ISO1997","profile_kind":null,"filter":null,"lambda_c_mm":0.8,"lambda_s_um":2.5,"sampling_lengths":5,"evaluation_length_mm":4.0,"speed_mm_s":0.5,"raw":"3120504.0012"}}
{"class":"line","index":0,"y_target_nm":-20000000,"y_readback_nm":-20000000,"attempt":1,"points":160,"csv_sha256":"00","time":"2026-01-01T00:01:00Z"}
{"class":"interruption","reason":"instrument absent","device":"instrument","line":1,"time":"2026-01-01T00:02:00Z"}
{"class":"line","index":1,"y_target_nm":-19990000,"y_readback_nm":null,"attempt":2,"points":160,"csv_sha256":"01","time":"2026-01-01T00:03:00Z"}
{"class":"stop","status":"success","reason":"complete","time":"2026-01-01T00:04:00Z"}
"#
    .to_vec();
    const EXTRA: &[&[u8]] = &[b"4294967295", b"-20000000", b"null", b"\"line\"", b"\n"];
    fuzz(
        3000,
        (inputs(vec![seed], EXTRA), any::<u32>()),
        |(b, total)| {
            let path = Path::new("journal.jsonl");
            if let Ok(rec) = parse_journal(path, &b) {
                if let Ok(state) = ResumeState::from_records(path, &rec.records) {
                    let _ = state.first_missing(total);
                    let _ = state.first_missing(8);
                    let _ = state.completed();
                }
            }
        },
    );
}

// --- control protocol ----------------------------------------------------------------

#[test]
fn control_protocol() {
    use bytes::BytesMut;
    use surfscan::control::protocol::{Message, Request};
    use surfscan::control::server::RequestCodec;
    use tokio_util::codec::Decoder;
    let seeds: Vec<Vec<u8>> = [
        r#"{"class":"status"}"#,
        r#"{"class":"watch"}"#,
        r#"{"class":"pause"}"#,
        r#"{"class":"start","specimen":"B12","operator":"R","notes":"n"}"#,
        r#"{"class":"hello","protocol":1,"software":"surfscan 0.1.0","pid":12}"#,
        r#"{"class":"ack","command":"pause","detail":"after this line"}"#,
        r#"{"class":"error","message":"busy"}"#,
    ]
    .iter()
    .map(|s| format!("{s}\r\n").into_bytes())
    .collect();
    const EXTRA: &[&[u8]] = &[
        b"\"class\":",
        b"\"status\"",
        b"null",
        b"\\u0000",
        b"\\ud800",
    ];
    fuzz(
        3000,
        (inputs(seeds, EXTRA), vec(1..16usize, 1..6)),
        |(b, chunks)| {
            let mut codec = RequestCodec::new(32);
            let mut buf = BytesMut::new();
            let mut rest = &b[..];
            for n in chunks.iter().cycle() {
                if rest.is_empty() {
                    break;
                }
                let (now, later) = rest.split_at((*n).min(rest.len()));
                rest = later;
                buf.extend_from_slice(now);
                while let Ok(Some(_)) = codec.decode(&mut buf) {}
            }
            while let Ok(Some(_)) = codec.decode_eof(&mut buf) {}
            let _ = serde_json::from_slice::<Request>(&b);
            let _ = serde_json::from_slice::<Message>(&b);
        },
    );
}

// --- IGES ----------------------------------------------------------------------------

fn small_surface() -> surfscan::nurbs::NurbsSurface {
    let (rows, cols) = (4, 5);
    let heights: Vec<f64> = (0..rows * cols)
        .map(|i| ((i * 7) % 11) as f64 * 0.1 - 0.5)
        .collect();
    let y: Vec<f64> = (0..rows).map(|j| j as f64 * 0.01).collect();
    let options = surfscan::fit::FitOptions::degrees(3, 2);
    surfscan::fit::fit_grid(0.0015, &y, &heights, cols, options)
        .unwrap()
        .surface
}

/// A valid IGES file taken apart into its sections' columns 1–72, so that mutated sections
/// can be laid out again as 80-column records with correct sequence numbers and Terminate
/// counts, and the reader's checks past the record layout are reached.
#[derive(Debug, Clone)]
struct IgesParts {
    /// Columns 1–72 of each record, per section S, G, D, P.
    sections: [Vec<Vec<u8>>; 4],
}

impl IgesParts {
    fn split(file: &[u8]) -> IgesParts {
        let mut sections: [Vec<Vec<u8>>; 4] = Default::default();
        for line in file.split(|&c| c == b'\n').filter(|l| l.len() >= 80) {
            if let Some(k) = b"SGDP".iter().position(|&c| c == line[72]) {
                sections[k].push(line[..72].to_vec());
            }
        }
        IgesParts { sections }
    }

    fn layout(&self) -> Vec<u8> {
        let mut out = Vec::new();
        let record = |out: &mut Vec<u8>, cols: &[u8], letter: u8, seq: usize| {
            let mut line = cols.to_vec();
            line.resize(72, b' ');
            line.truncate(72);
            out.extend_from_slice(&line);
            out.push(letter);
            out.extend_from_slice(format!("{seq:7}\n").as_bytes());
        };
        for (k, &letter) in b"SGDP".iter().enumerate() {
            for (i, cols) in self.sections[k].iter().enumerate() {
                record(&mut out, cols, letter, i + 1);
            }
        }
        let [s, g, d, p] = &self.sections;
        let t = format!("S{:7}G{:7}D{:7}P{:7}", s.len(), g.len(), d.len(), p.len());
        record(&mut out, t.as_bytes(), b'T', 1);
        out
    }
}

#[derive(Debug, Clone)]
enum IgesEdit {
    /// Mutate the Global section's parameter text (laid out again over as many records).
    Global(Vec<Edit>),
    /// Mutate one Parameter Data record's columns 1–64 (kept at 64 columns).
    Parameter(usize, Vec<Edit>),
    /// Put a number into one 8-column Directory Entry field.
    Directory(usize, usize, usize),
}

fn iges_edit() -> impl Strategy<Value = IgesEdit> {
    prop_oneof![
        vec(edit(), 1..4).prop_map(IgesEdit::Global),
        (any::<usize>(), vec(edit(), 1..4)).prop_map(|(i, e)| IgesEdit::Parameter(i, e)),
        (any::<usize>(), 0..9usize, any::<usize>())
            .prop_map(|(i, k, t)| IgesEdit::Directory(i, k, t)),
    ]
}

fn apply_iges(parts: &IgesParts, edits: &[IgesEdit], extra: &[&[u8]]) -> Vec<u8> {
    let mut parts = parts.clone();
    for e in edits {
        match e {
            IgesEdit::Global(edits) => {
                let text: Vec<u8> = parts.sections[1].concat();
                let text = apply(&text, edits, extra);
                parts.sections[1] = text.chunks(72).map(<[u8]>::to_vec).collect();
            }
            IgesEdit::Parameter(i, edits) => {
                let p = &mut parts.sections[3];
                let i = i % p.len();
                let mut cols = apply(&p[i][..64], edits, extra);
                cols.resize(64, b' ');
                cols.truncate(64);
                p[i].splice(..64, cols);
            }
            IgesEdit::Directory(i, k, t) => {
                let d = &mut parts.sections[2];
                let i = i % d.len();
                let n = NUMBERS[t % NUMBERS.len()];
                let n = &n[..n.len().min(8)];
                let field = &mut d[i][8 * k..8 * k + 8];
                field.fill(b' ');
                field[8 - n.len()..].copy_from_slice(n);
            }
        }
    }
    parts.layout()
}

#[test]
fn iges_reader() {
    use surfscan::iges::{read_iges, write_iges, IgesOptions};
    let mut bytes = Vec::new();
    let options = IgesOptions {
        start_lines: vec!["specimen: fuzz".into()],
        ..IgesOptions::default()
    };
    write_iges(&mut bytes, &[small_surface()], &options).unwrap();
    let parts = IgesParts::split(&bytes);
    assert_eq!(
        parts.layout(),
        bytes,
        "the test's layout must match the writer's"
    );
    const EXTRA: &[&[u8]] = &[
        b"18446744073709551615H",
        b"9223372036854775807H",
        b"1H,",
        b"128,",
        b"1.0D+308",
        b"0D0",
    ];
    let structured = vec(iges_edit(), 1..4).prop_map(move |e| Input(apply_iges(&parts, &e, EXTRA)));
    let strategy = prop_oneof![1 => inputs(vec![bytes], EXTRA), 3 => structured];
    fuzz(3000, strategy, |b| {
        if let Ok(file) = read_iges(&b) {
            for s in &file.surfaces {
                let _ = s.evaluate(0.5, 0.5);
            }
        }
    });
}

// --- X3P -----------------------------------------------------------------------------

/// A zip of stored entries with local headers only (all the reader looks at), so mutated
/// XML can be packed with its MD5 sums correct and reach the XML reader itself.
fn zip_local(entries: &[(&str, &[u8])]) -> Vec<u8> {
    let mut out = Vec::new();
    for (name, data) in entries {
        out.extend_from_slice(&0x0403_4b50u32.to_le_bytes());
        out.extend_from_slice(&[20, 0, 0, 0, 0, 0, 0, 0, 0x21, 0]);
        out.extend_from_slice(&surfscan::x3p::crc32(data).to_le_bytes());
        out.extend_from_slice(&(data.len() as u32).to_le_bytes());
        out.extend_from_slice(&(data.len() as u32).to_le_bytes());
        out.extend_from_slice(&(name.len() as u16).to_le_bytes());
        out.extend_from_slice(&0u16.to_le_bytes());
        out.extend_from_slice(name.as_bytes());
        out.extend_from_slice(data);
    }
    out
}

/// The XML of an archive written by `to_x3p` (3 × 4 heights) and its point data.
fn x3p_parts() -> (Vec<u8>, Vec<u8>, Vec<u8>) {
    use surfscan::metrology::areal::HeightMap;
    use surfscan::x3p::{to_x3p, X3pMeta};
    let heights: Vec<f64> = (0..12).map(|i| i as f64 * 0.1 - 0.3).collect();
    let meta = X3pMeta {
        creator: "fuzz".into(),
        ..X3pMeta::default()
    };
    let archive = to_x3p(
        &HeightMap {
            heights_um: &heights,
            rows: 3,
            cols: 4,
            pitch_x_mm: 0.0015,
            pitch_y_mm: 0.01,
        },
        (0.0, 0.0),
        &meta,
    )
    .unwrap();
    let xml_start = archive.windows(5).position(|w| w == b"<?xml").unwrap();
    let end_tag = b"</p:ISO5436_2>\n";
    let xml_end = archive
        .windows(end_tag.len())
        .position(|w| w == end_tag)
        .unwrap()
        + end_tag.len();
    let xml = archive[xml_start..xml_end].to_vec();
    let data: Vec<u8> = heights
        .iter()
        .flat_map(|z| (z * 1e-6).to_le_bytes())
        .collect();
    (archive, xml, data)
}

/// An archive of `xml` and `data` whose two MD5 sums are correct (the XML's data sum is
/// rewritten to match `data`), so the reader gets past them to the XML itself.
fn x3p_with(xml: &str, data: &[u8]) -> Vec<u8> {
    use surfscan::x3p::md5;
    let hex = |d: &[u8]| {
        md5(d)
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect::<String>()
    };
    let (open, close) = ("<MD5ChecksumPointData>", "</MD5ChecksumPointData>");
    let xml = match (xml.find(open), xml.find(close)) {
        (Some(s), Some(e)) if s + open.len() <= e => {
            format!("{}{}{}", &xml[..s + open.len()], hex(data), &xml[e..])
        }
        _ => xml.to_owned(),
    };
    let sums = format!("{} *main.xml\n", hex(xml.as_bytes()));
    zip_local(&[
        ("main.xml", xml.as_bytes()),
        ("bindata/data.bin", data),
        ("md5checksum.hex", sums.as_bytes()),
    ])
}

#[test]
fn x3p_reader() {
    use surfscan::x3p::read_x3p;
    let (archive, xml, data) = x3p_parts();
    const EXTRA: &[&[u8]] = &[
        b"<SizeX>",
        b"</SizeX>",
        b"<SizeY>1e300</SizeY>",
        b"-1",
        b"&amp;",
    ];
    let raw = inputs(vec![archive], EXTRA);
    let other_data = vec(any::<u8>(), 0..200).prop_map(Input);
    let repacked = (inputs(vec![xml], EXTRA), other_data, any::<bool>());
    fuzz(
        3000,
        (raw, repacked),
        |(raw, (xml, other_data, keep_data))| {
            let _ = read_x3p(&raw);
            let data = if keep_data {
                &data[..]
            } else {
                &other_data[..]
            };
            let _ = read_x3p(&x3p_with(&text(&xml), data));
        },
    );
}

// --- regressions: each panic the fuzzing found, pinned by the input that found it -----

#[test]
fn x3p_size_y_1e300_is_an_error_not_an_overflow() {
    use surfscan::x3p::read_x3p;
    let (_, xml, data) = x3p_parts();
    let xml = crate::common::edited(&text(&xml), "<SizeY>3</SizeY>", "<SizeY>1e300</SizeY>");
    assert!(read_x3p(&x3p_with(&xml, &data)).is_err());
    // Sizes are whole numbers; their product must not overflow either.
    let xml = crate::common::edited(
        &xml,
        "<SizeY>1e300</SizeY>",
        &format!("<SizeY>{}</SizeY>", usize::MAX),
    );
    assert!(read_x3p(&x3p_with(&xml, &data)).is_err());
    // The unchanged parts still read.
    let (_, xml, data) = x3p_parts();
    assert_eq!(read_x3p(&x3p_with(&text(&xml), &data)).unwrap().rows, 3);
}

#[test]
fn iges_hollerith_count_of_usize_max_is_an_error_not_an_overflow() {
    use surfscan::iges::{read_iges, write_iges, IgesOptions};
    let mut bytes = Vec::new();
    write_iges(&mut bytes, &[small_surface()], &IgesOptions::default()).unwrap();
    let mut parts = IgesParts::split(&bytes);
    let g = parts.sections[1].concat();
    let g =
        String::from_utf8(g)
            .unwrap()
            .replacen("8Hsurfscan", "18446744073709551615Hsurfscan", 1);
    parts.sections[1] = g.as_bytes().chunks(72).map(<[u8]>::to_vec).collect();
    let e = read_iges(&parts.layout()).unwrap_err().to_string();
    assert!(e.contains("Hollerith"), "{e}");
}
