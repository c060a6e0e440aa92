//! The web gateway (`idmesh web`) in front of a real deployment, seen as a
//! person and their tools would: a real browser (Debian's headless
//! Chromium over the DevTools protocol) opens the live map, `curl`-like
//! REST and Server-Sent Events get the Zenoh API's answers byte for byte,
//! and `/metrics` parses with a real OpenMetrics parser and says what
//! `query/stats` says. Killing a leader turns the page `degraded`, naming
//! it. Screenshots and the figures are written to the test's output
//! directory (`target/tmp/web/`).

use idmesh_tests::{crowd_with_identities, Chromium, Deployment, Factored, Gateway, Settings};
use serde_json::Value;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

const TRACKS: usize = 16;

fn output_dir() -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("web");
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// GET `url` with `accept`: (status, body).
fn get(url: &str) -> (u16, Vec<u8>) {
    let response = match ureq::get(url).timeout(Duration::from_secs(30)).call() {
        Ok(r) => r,
        Err(ureq::Error::Status(_, r)) => r,
        Err(e) => panic!("GET {url}: {e}"),
    };
    let status = response.status();
    let mut body = Vec::new();
    std::io::Read::read_to_end(&mut response.into_reader(), &mut body).unwrap();
    (status, body)
}

fn json(body: &[u8]) -> Value {
    serde_json::from_slice(body)
        .unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(body)))
}

/// `idmesh query <args> --json`, the bytes it printed (one answer).
fn zenoh_answer(deployment: &Deployment, args: &[&str]) -> Vec<u8> {
    let output = std::process::Command::new(idmesh_tests::idmesh())
        .arg("query")
        .args(args)
        .args(["--json", "--connect", &deployment.coordinator])
        .args(["--prefix", &deployment.prefix])
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let mut body = output.stdout;
    assert_eq!(body.pop(), Some(b'\n'));
    body
}

/// The first `count` events of a Server-Sent Events stream: (event name,
/// data, when it came).
fn sse(url: &str, count: usize) -> Vec<(String, String, Instant)> {
    let response = ureq::get(url)
        .set("Accept", "text/event-stream")
        .timeout(Duration::from_secs(60))
        .call()
        .unwrap_or_else(|e| panic!("SSE {url}: {e}"));
    assert_eq!(response.content_type(), "text/event-stream");
    let mut events = Vec::new();
    let (mut name, mut data) = (String::new(), String::new());
    for line in BufReader::new(response.into_reader()).lines() {
        let line = line.unwrap();
        if let Some(n) = line.strip_prefix("event:") {
            name = n.trim().to_string();
        } else if let Some(d) = line.strip_prefix("data:") {
            data.push_str(d.strip_prefix(' ').unwrap_or(d));
        } else if line.is_empty() && !data.is_empty() {
            events.push((
                std::mem::take(&mut name),
                std::mem::take(&mut data),
                Instant::now(),
            ));
            if events.len() == count {
                break;
            }
        }
    }
    events
}

fn snapshot(tab: &mut Chromium) -> Value {
    serde_json::from_str(&tab.eval("JSON.stringify(window.idmesh.snapshot())")).unwrap()
}

/// Polls the page until `wanted` holds of its snapshot.
fn page_when(
    tab: &mut Chromium,
    patience: Duration,
    what: &str,
    wanted: impl Fn(&Value) -> bool,
) -> Value {
    let started = Instant::now();
    loop {
        let s = snapshot(tab);
        if wanted(&s) {
            return s;
        }
        if started.elapsed() > patience {
            let mut s = s;
            s["tracks"] = Value::from(s["tracks"].as_array().map_or(0, Vec::len));
            panic!("the page never showed {what} within {patience:?}; last: {s}");
        }
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// The colour of the canvas pixel under (x, y) CSS pixels.
fn pixel(tab: &mut Chromium, x: f64, y: f64, ratio: f64) -> [u8; 3] {
    let js = format!(
        "Array.from(document.getElementById('map').getContext('2d').getImageData({}, {}, 1, 1).data).join(',')",
        (x * ratio).round(),
        (y * ratio).round()
    );
    let parts: Vec<u8> = tab
        .eval(&js)
        .split(',')
        .map(|p| p.parse().unwrap())
        .collect();
    [parts[0], parts[1], parts[2]]
}

/// The map's colour of P(red) = p (the page's ramp, written again here).
fn colour_of(p: f64) -> [i32; 3] {
    let q = p.clamp(0.0, 1.0);
    [
        (49.0 + 180.0 * q).round() as i32,
        (130.0 - 68.0 * q).round() as i32,
        (206.0 - 144.0 * q).round() as i32,
    ]
}

fn percentile(mut xs: Vec<f64>, q: f64) -> f64 {
    xs.sort_by(f64::total_cmp);
    xs[((xs.len() - 1) as f64 * q).round() as usize]
}

#[test]
fn the_live_map_rest_sse_and_metrics_show_what_the_zenoh_api_answers() {
    let out = output_dir();
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-web");
    let trace = crowd_with_identities(&dir, TRACKS, 4, 120.0, 3);
    let settings = Settings {
        leaders: 4,
        distributed_rule: true,
        budget: 300,
        rate: Some(400.0),
        ..Settings::default()
    };
    let mut deployment = Deployment::start_each("web", &trace, &settings);
    let gateway = Gateway::start(&deployment);
    let prefix = deployment.prefix.clone();
    let api = |q: &str| gateway.at(&format!("{prefix}/query/{q}"));

    // The health checks: up at once; ready once every role answers.
    assert_eq!(get(&gateway.at("healthz")).0, 200);
    let started = Instant::now();
    while get(&gateway.at("readyz")).0 != 200 {
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "never ready: {}",
            String::from_utf8_lossy(&get(&gateway.at("readyz")).1)
        );
        std::thread::sleep(Duration::from_millis(200));
    }

    // The page, opened while the stream runs.
    let mut tab = Chromium::start(&out, 1400, 900);
    let opened = Instant::now();
    tab.open(&gateway.url);
    let first = page_when(&mut tab, Duration::from_secs(60), "a first map", |s| {
        s["firstMapMs"].is_number()
    });
    let first_map_ms = first["firstMapMs"].as_f64().unwrap();
    let seen_from_here = opened.elapsed();

    // Once the stream is over every answer is final: the REST and Zenoh
    // answers are the same bytes.
    let last = deployment.final_marginals(Duration::from_secs(120));
    let events = last["watermark"]["sensor-0"].as_u64().unwrap();
    for (path, args) in [
        ("marginals", vec!["marginals"]),
        ("track/3", vec!["track", "3"]),
        ("identity", vec!["identity"]),
        ("identity/5", vec!["identity", "5"]),
        ("positions", vec!["positions"]),
    ] {
        let (status, body) = get(&api(path));
        assert_eq!(status, 200, "{path}: {}", String::from_utf8_lossy(&body));
        let zenoh = zenoh_answer(&deployment, &args);
        assert_eq!(
            String::from_utf8_lossy(&body),
            String::from_utf8_lossy(&zenoh),
            "GET {path} and the Zenoh answer differ"
        );
    }
    let marginals = get(&api("marginals")).1;
    let positions = json(&get(&api("positions")).1);
    assert_eq!(positions["tracks"], TRACKS);
    assert_eq!(positions["watermark"]["sensor-0"], events);
    assert_eq!(positions["leaders"].as_array().unwrap().len(), 4);

    // SSE: the same answer as a stream, at the interval asked for.
    let streamed = sse(&format!("{}?interval=200", api("marginals")), 8);
    let answers: Vec<_> = streamed.iter().filter(|e| e.0 == "answer").collect();
    let latencies: Vec<f64> = streamed
        .iter()
        .filter(|e| e.0 == "latency")
        .map(|e| json(e.1.as_bytes())["ms"].as_f64().unwrap())
        .collect();
    assert_eq!(answers.len(), 4);
    for (_, data, _) in &answers {
        assert_eq!(data.as_bytes(), marginals.as_slice());
    }
    let gap = answers[3].2 - answers[1].2;
    assert!(
        gap >= Duration::from_millis(350),
        "two intervals of 200 ms took {gap:?}"
    );

    // Bad questions: the coordinator's error, with a 4xx status.
    for (path, status, says) in [
        ("track/abc", 400, "\"abc\""),
        ("track/999", 400, "out of range"),
        ("marginals?events=abc", 400, "events=abc"),
        ("marginals?event=5", 400, "unknown parameter"),
        ("marginals?events=1", 400, "past event 1"),
        ("stats?events=3", 400, "no parameters"),
        ("bogus", 404, "no such question"),
        ("marginals?interval=5", 400, "interval=5"),
    ] {
        let (got, body) = get(&api(path));
        let error = json(&body)["error"]
            .as_str()
            .unwrap_or_default()
            .to_string();
        assert_eq!(got, status, "{path}: {error}");
        assert!(error.contains(says), "{path}: {error}");
    }
    let (got, body) = get(&gateway.at(&format!("{prefix}/leader/leader-0/stats")));
    assert_eq!(got, 404, "{}", String::from_utf8_lossy(&body));

    // /metrics: a real OpenMetrics parser reads it, and it says what
    // query/stats says.
    let stats = json(&zenoh_answer(&deployment, &["stats"]));
    let (status, text) = get(&gateway.at("metrics"));
    assert_eq!(status, 200);
    let text = String::from_utf8(text).unwrap();
    std::fs::write(out.join("metrics.txt"), &text).unwrap();
    let exposition = openmetrics_parser::openmetrics::parse_openmetrics(&text)
        .unwrap_or_else(|e| panic!("not OpenMetrics: {e:?}\n{text}"));
    let value = |family: &str, leader: &str| -> f64 {
        let family = exposition
            .families
            .get(family)
            .unwrap_or_else(|| panic!("no family {family}"));
        let sample = family
            .iter_samples()
            .find(|s| {
                s.get_labelset()
                    .ok()
                    .and_then(|l| l.get_label_value("leader").map(|v| v == leader))
                    .unwrap_or(false)
            })
            .unwrap_or_else(|| panic!("{leader} in {}", family.family_name));
        match &sample.value {
            openmetrics_parser::OpenMetricsValue::Counter(c) => c.value.as_f64(),
            openmetrics_parser::OpenMetricsValue::Gauge(g) => g.as_f64(),
            other => panic!("{other:?}"),
        }
    };
    for leader in stats["leaders"].as_array().unwrap() {
        let name = leader["leader"].as_str().unwrap();
        for (family, field) in [
            ("idmesh_leader_items", "items"),
            ("idmesh_leader_mixes", "mixes"),
            ("idmesh_leader_bytes_sent", "bytes_sent"),
            ("idmesh_leader_sets_sent", "sets_sent"),
            ("idmesh_leader_coefficients", "coefficients"),
            ("idmesh_leader_rows_held", "rows_held"),
        ] {
            assert_eq!(
                value(family, name),
                leader[field].as_u64().unwrap() as f64,
                "{family} of {name}"
            );
        }
    }
    assert!(exposition
        .families
        .contains_key("idmesh_web_query_latency_seconds"));

    // The map at the final watermark: every track, coloured by the
    // marginals the API answers there.
    let expected = json(&marginals);
    let p_red: Vec<f64> = expected["p_red"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p.as_f64().unwrap())
        .collect();
    let page = page_when(
        &mut tab,
        Duration::from_secs(30),
        "the final watermark",
        |s| s["watermark"] == events && s["positionsAt"] == events && s["finished"] == true,
    );
    let shown = page["tracks"].as_array().unwrap();
    assert_eq!(shown.len(), TRACKS);
    assert_eq!(page["status"], "live", "{page}");
    let ratio = page["ratio"].as_f64().unwrap();
    let mut checked = 0;
    for (t, track) in shown.iter().enumerate() {
        assert_eq!(track["track"], t);
        let p = track["p_red"].as_f64().unwrap();
        assert!(
            (p - p_red[t]).abs() < 1e-12,
            "track {t}: {p} vs {}",
            p_red[t]
        );
        let (x, y) = (track["x"].as_f64().unwrap(), track["y"].as_f64().unwrap());
        // A track drawn over by a neighbour cannot be read off the canvas.
        let covered = shown.iter().enumerate().any(|(u, o)| {
            u != t
                && (o["x"].as_f64().unwrap() - x).abs() < 70.0
                && (o["y"].as_f64().unwrap() - y).abs() < 20.0
        });
        if covered {
            continue;
        }
        let got = pixel(&mut tab, x, y, ratio);
        let want = colour_of(p_red[t]);
        assert!(
            (0..3).all(|i| (got[i] as i32 - want[i]).abs() <= 2),
            "track {t} P(red) = {}: pixel {got:?}, expected {want:?}",
            p_red[t]
        );
        checked += 1;
    }
    assert!(
        checked >= 3,
        "only {checked} tracks could be read off the map"
    );
    let table = tab.eval(
        "Array.from(document.querySelectorAll('#tracks tbody tr')).map(r => r.children[1].textContent).join(',')",
    );
    let rows: Vec<String> = p_red.iter().map(|p| format!("{p:.3}")).collect();
    assert_eq!(table, rows.join(","));
    std::fs::write(out.join("map.png"), tab.screenshot()).unwrap();

    // Figures: a direct Zenoh query against the same through the gateway.
    let direct: Vec<f64> = (0..30)
        .map(|_| {
            let started = Instant::now();
            zenoh_answer(&deployment, &["marginals"]);
            started.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    let rest: Vec<f64> = (0..30)
        .map(|_| {
            let started = Instant::now();
            assert_eq!(get(&api("marginals")).0, 200);
            started.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    let streamed = sse(&format!("{}?interval=100", api("marginals")), 60);
    let sse_ms: Vec<f64> = streamed
        .iter()
        .filter(|e| e.0 == "latency")
        .map(|e| json(e.1.as_bytes())["ms"].as_f64().unwrap())
        .chain(latencies)
        .collect();
    let figures = format!(
        "page load to first map: {first_map_ms:.0} ms in the page ({:.0} ms from navigation asked)\n\
         marginals, stream over, {TRACKS} tracks, 4 leaders (p50 / p99 ms):\n\
         - `idmesh query` process (Zenoh session opened each time): {:.1} / {:.1}\n\
         - REST GET through the gateway: {:.2} / {:.2}\n\
         - SSE update: the gateway's wait for each answer: {:.2} / {:.2}\n",
        seen_from_here.as_secs_f64() * 1e3,
        percentile(direct.clone(), 0.5),
        percentile(direct, 0.99),
        percentile(rest.clone(), 0.5),
        percentile(rest, 0.99),
        percentile(sse_ms.clone(), 0.5),
        percentile(sse_ms, 0.99),
    );
    std::fs::write(out.join("figures.md"), &figures).unwrap();
    eprintln!("{figures}");

    // A leader killed: the page says degraded and names it, the API
    // answers 503 with the coordinator's error, /readyz names it too.
    deployment.kill("leader-1");
    let degraded = page_when(&mut tab, Duration::from_secs(60), "degraded", |s| {
        s["status"] == "degraded" && s["statusText"].as_str().unwrap_or("").contains("leader-1")
    });
    assert!(
        degraded["problem"].as_str().unwrap().contains("leader-1"),
        "{degraded}"
    );
    std::fs::write(out.join("degraded.png"), tab.screenshot()).unwrap();
    let (status, body) = get(&api("marginals"));
    assert_eq!(status, 503);
    let error = json(&body)["error"].as_str().unwrap().to_string();
    assert!(
        error.starts_with("degraded") && error.contains("leader-1"),
        "{error}"
    );
    let (status, body) = get(&gateway.at("readyz"));
    assert_eq!(status, 503);
    assert_eq!(json(&body)["missing"], serde_json::json!(["leader-1"]));
    let (status, text) = get(&gateway.at("metrics"));
    assert_eq!(status, 200);
    let text = String::from_utf8(text).unwrap();
    assert!(
        text.lines().any(
            |l| l.starts_with("idmesh_coordinator_degraded_answers_total") && !l.ends_with(" 0")
        ),
        "{text}"
    );
}

/// A box of the page's map (CSS pixels from the canvas's corner): a
/// label as the browser laid it out, or a marker.
#[derive(Debug)]
struct Drawn {
    key: String,
    left: f64,
    top: f64,
    width: f64,
    height: f64,
    selected: bool,
}

impl Drawn {
    fn read(v: &Value) -> Drawn {
        let number = |f: &str| v[f].as_f64().unwrap_or_else(|| panic!("{f} of {v}"));
        Drawn {
            key: v["key"].as_str().unwrap_or_default().to_string(),
            left: number("left"),
            top: number("top"),
            width: number("width"),
            height: number("height"),
            selected: v["selected"] == true,
        }
    }

    /// Whether two boxes share more than a sliver (sub-pixel rounding of
    /// boxes that touch is not an overlap).
    fn covers(&self, other: &Drawn) -> bool {
        let across =
            (self.left + self.width).min(other.left + other.width) - self.left.max(other.left);
        let down = (self.top + self.height).min(other.top + other.height) - self.top.max(other.top);
        across > 0.5 && down > 0.5
    }
}

/// The page's labels as laid out, its markers, and every pair where a
/// label covers another label or a marker (the selected track's label
/// may cover a marker: it is shown whatever is there).
/// [`label_overlaps`] once the page has drawn what `drawn` asks of its
/// labels (the positions can come a frame before the labels do), or
/// after 15 s, for the caller's assertions to name what is missing.
fn settled_labels(
    tab: &mut Chromium,
    drawn: impl Fn(&[Drawn]) -> bool,
) -> (Vec<Drawn>, Vec<String>) {
    let started = Instant::now();
    loop {
        let measured = label_overlaps(tab);
        if drawn(&measured.0) || started.elapsed() > Duration::from_secs(15) {
            return measured;
        }
        std::thread::sleep(Duration::from_millis(200));
    }
}

fn label_overlaps(tab: &mut Chromium) -> (Vec<Drawn>, Vec<String>) {
    let shown: Value = serde_json::from_str(&tab.eval("JSON.stringify(window.idmesh.labels())"))
        .expect("the page's labels");
    let read = |what: &str| -> Vec<Drawn> {
        let all = shown[what].as_array();
        all.unwrap_or_else(|| panic!("no {what}: {shown}"))
            .iter()
            .map(Drawn::read)
            .collect()
    };
    let (labels, markers) = (read("labels"), read("markers"));
    let mut overlaps = Vec::new();
    for (i, a) in labels.iter().enumerate() {
        for b in &labels[i + 1..] {
            if a.covers(b) {
                overlaps.push(format!("label {} covers label {}", a.key, b.key));
            }
        }
        for m in markers.iter().filter(|_| !a.selected) {
            if a.covers(m) {
                overlaps.push(format!("label {} covers marker {}", a.key, m.key));
            }
        }
    }
    (labels, overlaps)
}

/// The demo's scene — a simulated crowd of forty with identity reads, four
/// leaders on fitted regions — opened once its stream is over: the charts
/// show the stream that was (from the gateway's history), the leaders sit
/// inside their regions, and no label covers another label or a marker.
/// The same measurement on the same scene with placement turned off
/// finds overlaps, so it would see them.
#[test]
fn the_map_of_a_crowd_places_labels_apart_and_remembers_the_charts() {
    let out = output_dir();
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-web-map");
    let trace = crowd_with_identities(&dir, 40, 10, 60.0, 1);
    // The demo's settings: the factored belief, regions fitted.
    let settings = Settings {
        leaders: 4,
        rate: Some(500.0),
        factored: Some(Factored::default()),
        ..Settings::default()
    };
    let deployment = Deployment::start("web-map", &trace, &settings);
    let gateway = Gateway::start(&deployment);
    let last = deployment.final_marginals(Duration::from_secs(120));
    let events = idmesh_tests::watermark_events(&last);

    // The history outlives the stream: rates of the stream that was.
    let started = Instant::now();
    let history = loop {
        let history = json(&get(&gateway.at("history")).1);
        let samples = history["samples"].as_array().cloned().unwrap_or_default();
        let at_end = samples.iter().any(|s| s["events"] == events);
        if at_end || started.elapsed() > Duration::from_secs(30) {
            break samples;
        }
        std::thread::sleep(Duration::from_millis(500));
    };
    let peak = history
        .iter()
        .filter_map(|s| s["rate"].as_f64())
        .fold(0.0, f64::max);
    assert!(peak > 0.0, "no rate in the history: {history:?}");
    assert!(history.iter().any(|s| s["events"] == events));

    // The page, opened after the stream: its charts start from the past.
    let mut tab = Chromium::start(&out, 1400, 900);
    tab.open(&gateway.url);
    let page = page_when(&mut tab, Duration::from_secs(30), "the final map", |s| {
        s["positionsAt"] == events && s["finished"] == true && s["peakRate"].as_f64() > Some(0.0)
    });
    assert_ne!(page["rate"], "–", "{page}");
    let positions = json(&get(&gateway.at(&format!("{}/query/positions", deployment.prefix))).1);
    for leader in positions["leaders"].as_array().unwrap() {
        let (at, region) = (&leader["at"], &leader["region"]);
        let centre =
            |i: usize| (region[i].as_f64().unwrap() + region[i + 2].as_f64().unwrap()) / 2.0;
        assert_eq!(
            (at[0].as_f64(), at[1].as_f64()),
            (Some(centre(0)), Some(centre(1))),
            "{leader}"
        );
    }

    // A selected track's label is always shown; no label covers another.
    tab.eval("window.idmesh.select(0), 'ok'");
    let (labels, overlaps) = settled_labels(&mut tab, |labels| {
        labels
            .iter()
            .filter(|l| l.key.starts_with("leader"))
            .count()
            == 4
            && labels.len() >= 20
    });
    std::fs::write(out.join("labels.png"), tab.screenshot()).unwrap();
    assert!(overlaps.is_empty(), "{overlaps:#?}");
    assert!(labels.iter().any(|l| l.key == "track 0" && l.selected));
    let leaders = labels
        .iter()
        .filter(|l| l.key.starts_with("leader"))
        .count();
    assert_eq!(leaders, 4, "{labels:?}");
    assert!(labels.len() >= 20, "only {} labels shown", labels.len());

    // Without placement, the same scene measured the same way overlaps.
    tab.open(&format!("{}/?placement=off", gateway.url));
    page_when(&mut tab, Duration::from_secs(30), "the final map", |s| {
        s["positionsAt"] == events
    });
    let (crowded, overlaps) = settled_labels(&mut tab, |labels| labels.len() == 40 + 4);
    std::fs::write(out.join("labels-unplaced.png"), tab.screenshot()).unwrap();
    assert_eq!(crowded.len(), 40 + 4);
    assert!(
        overlaps.len() >= 3,
        "the unplaced map should overlap: {overlaps:?}"
    );
}
