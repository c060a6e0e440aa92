//! The factored belief as the live distributed belief, as real
//! processes on loopback: leaders hold components, a mix of components of
//! two leaders gathers them at one, a handover moves what leaves a region,
//! and the coordinator couples the components' count vectors at a query.
//! Asked at every truth line of a crowd, the deployment's marginals equal
//! `idmesh replay --method factored --coupling local` with the same
//! options to 1e-9 through 1, 2, 4 and 8 leaders, from a known start and
//! from the uniform prior, with leaders' interests growing in half the
//! deployments and shrinking in the other half (those under flow control:
//! the sensor at most a small window past the slowest leader); and a
//! leader killed mid-stream and restarted from its journal changes no
//! answer, while the window holds the stream for it. A stream of colours
//! and identities runs the factored belief too, with the information
//! matrix's rows beside it, and answers both as replay does through a
//! leader's crash.

use idmesh_tests::deployment::{
    crowd, crowd_with_identities, regions_argument, replay_lines, truth_lines, Deployment,
    Factored, LeaderFaultSection, Settings, SplitSetting, Truth,
};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The options of both sides: small components, so that splits happen.
const MAX_COMPONENT: usize = 3;

fn belief(shrink_interest: bool) -> Factored {
    Factored {
        max_component: MAX_COMPONENT as u32,
        split: SplitSetting::Original,
        shrink_interest,
        regional: false,
    }
}

fn central(trace: &Path) -> Vec<Value> {
    central_with(trace, &[])
}

fn central_with(trace: &Path, more: &[&str]) -> Vec<Value> {
    let max = MAX_COMPONENT.to_string();
    let mut args = vec![
        "--method",
        "factored",
        "--coupling",
        "local",
        "--max-component",
        &max,
        "--split",
        "original",
    ];
    args.extend_from_slice(more);
    replay_lines(trace, &args)
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap_or_else(|| panic!("an array: {v}"))
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

/// The same crowd without its known start: the uniform prior over red sets.
fn without_start(trace: &Path) -> PathBuf {
    let text = std::fs::read_to_string(trace).unwrap();
    let mut lines = text.lines();
    let mut header: Value = serde_json::from_str(lines.next().unwrap()).unwrap();
    assert!(
        header.get("initial_red").is_some(),
        "the crowd has a known start"
    );
    header.as_object_mut().unwrap().remove("initial_red");
    let mut out = serde_json::to_string(&header).unwrap();
    for line in lines {
        out.push('\n');
        out.push_str(line);
    }
    out.push('\n');
    let path = trace.with_extension("uniform.jsonl");
    std::fs::write(&path, out).unwrap();
    path
}

/// Every answer at a truth point equals the centralized one there, to 1e-9;
/// at least half the points are answered (a fresh query process may come
/// after the stream passed some, which are refused, never answered wrong).
fn check_points(what: &str, deployment: &Deployment, truths: &[Truth], central: &[Value]) {
    let answers = deployment.at_truth_points("marginals", truths);
    for (i, answer) in &answers {
        let got = floats(&answer["p_red"]);
        let want = floats(&central[*i]["p_red"]);
        assert_eq!(got.len(), want.len());
        for (t, (g, w)) in got.iter().zip(&want).enumerate() {
            assert!(
                (g - w).abs() < 1e-9,
                "{what}, truth line {i}, track {t}: {g} vs {w}\n{}",
                deployment.log()
            );
        }
    }
    assert!(
        answers.len() * 2 >= truths.len(),
        "{what}: only {} of {} truth points answered\n{}",
        answers.len(),
        truths.len(),
        deployment.log()
    );
}

/// The flow-control window of the deployments whose interests shrink:
/// small, so that the stream is held again and again.
const WINDOW: u64 = 8;

fn settings(leaders: usize, shrink_interest: bool) -> Settings {
    Settings {
        leaders,
        rate: Some(300.0),
        factored: Some(belief(shrink_interest)),
        window: shrink_interest.then_some(WINDOW),
        ..Settings::default()
    }
}

#[test]
fn factored_leaders_equal_the_centralized_local_rule_through_1_2_4_8_leaders() {
    let dir = std::env::temp_dir().join(format!("idmesh-factored-{}", std::process::id()));
    let known = crowd(&dir, 12, 4, 60.0, 5);
    for (s, (start, trace)) in [
        ("known start", known.clone()),
        ("uniform prior", without_start(&known)),
    ]
    .into_iter()
    .enumerate()
    {
        let central = central(&trace);
        let truths = truth_lines(&trace);
        assert_eq!(central.len(), truths.len());
        for (l, leaders) in [1, 2, 4, 8].into_iter().enumerate() {
            let shrink = (s + l) % 2 == 1;
            let name = format!("factored{leaders}{}", start.len());
            let deployment = Deployment::start(&name, &trace, &settings(leaders, shrink));
            deployment.first_answer(Duration::from_secs(30));
            let what = format!(
                "{start}, {leaders} leaders, interests {}",
                if shrink { "shrinking" } else { "growing" }
            );
            check_points(&what, &deployment, &truths, &central);
            let last = deployment.final_marginals(Duration::from_secs(60));
            let want = floats(&central.last().unwrap()["p_red"]);
            for (g, w) in floats(&last["p_red"]).iter().zip(&want) {
                assert!((g - w).abs() < 1e-9, "{what}, final: {g} vs {w}");
            }
            if leaders > 1 {
                // Tracks crossed regions and components moved between
                // leaders; every observation reached one holder only.
                let handovers = deployment.leaders_total("handovers");
                let moved = deployment.leaders_total("sets_sent");
                assert!(
                    handovers > 0 && moved > 0,
                    "{what}: {handovers} handovers, {moved} moved"
                );
            }
            // Components left leaders, and with them the tracks they
            // followed; growing interests never unfollow.
            let unfollows = deployment.leaders_total("unfollows");
            assert_eq!(
                unfollows > 0,
                shrink && leaders > 1,
                "{what}: {unfollows} unfollow requests"
            );
            let observations = deployment.leaders_total("observations");
            let in_trace = std::fs::read_to_string(&trace)
                .unwrap()
                .lines()
                .filter(|l| l.contains("\"observe\""))
                .count() as u64;
            assert!(
                observations >= in_trace,
                "{what}: {observations} observations applied of {in_trace}"
            );
            eprintln!(
                "{what}: {observations} observation items for {in_trace} observations, \
                 coefficients {}",
                last["coefficients"]
            );
        }
    }
}

/// A leader killed mid-stream and restarted from its journal and snapshot
/// (interests shrinking: its unfollow requests, lost or made again, change
/// nothing): the final answer still equals the centralized one.
#[test]
fn a_factored_leader_killed_and_restarted_changes_no_answer() {
    killed_and_restarted(false);
}

/// The same under the regional rule, against `idmesh replay --regions`.
#[test]
fn a_regional_leader_killed_and_restarted_changes_no_answer() {
    killed_and_restarted(true);
}

fn killed_and_restarted(regional: bool) {
    let dir = std::env::temp_dir().join(format!(
        "idmesh-factored-crash-{regional}-{}",
        std::process::id()
    ));
    let trace = crowd(&dir, 12, 4, 90.0, 5);
    let regions = regions_argument(&trace, 4);
    let central = match regional {
        true => central_with(&trace, &["--regions", &regions]),
        false => central(&trace),
    };
    let want = floats(&central.last().unwrap()["p_red"]);
    let settings = Settings {
        leaders: 4,
        rate: Some(500.0),
        journal: true,
        snapshot_every: Some(40),
        takeover_after_ms: Some(0),
        factored: Some(Factored {
            regional,
            ..belief(true)
        }),
        window: Some(WINDOW),
        ..Settings::default()
    };
    let name = format!("factored-crash-{regional}");
    let mut crashed = Deployment::start_each(&name, &trace, &settings);
    let first = crashed.first_answer(Duration::from_secs(30));
    assert_eq!(first["finished"], false, "the stream has begun, not ended");
    std::thread::sleep(Duration::from_millis(400));
    crashed.kill("leader-1");
    let error = crashed
        .query(&["marginals"])
        .expect_err("no answer without leader-1");
    assert!(error.contains("leader-1"), "the error names it: {error}");
    std::thread::sleep(Duration::from_millis(600));
    crashed.launch("leader", "leader-1");
    let last = crashed.final_marginals(Duration::from_secs(60));
    for (t, (g, w)) in floats(&last["p_red"]).iter().zip(&want).enumerate() {
        assert!((g - w).abs() < 1e-9, "after a crash, track {t}: {g} vs {w}");
    }
    // The window held the stream while leader-1 was away (the stream
    // could not run more than it past it).
    let stats = crashed.query(&["stats"]).expect("stats");
    let holds = stats[0]["sensors"][0]["window_holds"].as_u64().unwrap();
    assert!(holds > 0, "the window never held the stream: {stats:?}");
    assert!(
        crashed.leaders_total("snapshots") > 0,
        "leaders wrote snapshots"
    );
    assert!(crashed.leader("leader-1")["recoveries"].as_u64().unwrap() > 0);
    // The window held the stream while leader-1 was away: it was killed
    // mid-stream.
    let stats = crashed.query(&["stats"]).expect("stats");
    let holds = stats[0]["sensors"][0]["window_holds"].as_u64().unwrap();
    assert!(holds > 0, "the window never held the stream: {stats:?}");
}

/// The regional rule (`regional = true`): a mix across two leaders'
/// regions keeps its components apart, a track handed over is split off its
/// component. Through 2, 4 and 8 leaders the deployment equals `idmesh
/// replay --regions` with the same leaders' places at every truth line, to
/// 1e-9; that replay differs from the plain local rule's (the rule did
/// something), and the leaders moved fewer components than without it.
#[test]
fn regional_leaders_equal_the_centralized_regional_rule_through_2_4_8_leaders() {
    let dir = std::env::temp_dir().join(format!("idmesh-regional-{}", std::process::id()));
    let known = crowd(&dir, 12, 4, 60.0, 5);
    let plain = central(&known);
    for (l, leaders) in [2usize, 4, 8].into_iter().enumerate() {
        let (start, trace) = match l {
            1 => ("uniform prior", without_start(&known)),
            _ => ("known start", known.clone()),
        };
        let regions = regions_argument(&trace, leaders);
        let central = central_with(&trace, &["--regions", &regions]);
        let truths = truth_lines(&trace);
        assert_eq!(central.len(), truths.len());
        if l != 1 {
            let last = |v: &[Value]| floats(&v.last().unwrap()["p_red"]);
            let gap = last(&central)
                .iter()
                .zip(last(&plain))
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            assert!(
                gap > 1e-6,
                "{leaders} leaders: the regional rule changed nothing"
            );
        }
        let shrink = l % 2 == 0;
        let settings = Settings {
            factored: Some(Factored {
                regional: true,
                ..belief(shrink)
            }),
            ..settings(leaders, shrink)
        };
        let name = format!("regional{leaders}");
        let deployment = Deployment::start(&name, &trace, &settings);
        deployment.first_answer(Duration::from_secs(30));
        let what = format!("regional rule, {start}, {leaders} leaders");
        check_points(&what, &deployment, &truths, &central);
        let last = deployment.final_marginals(Duration::from_secs(60));
        let want = floats(&central.last().unwrap()["p_red"]);
        for (g, w) in floats(&last["p_red"]).iter().zip(&want) {
            assert!((g - w).abs() < 1e-9, "{what}, final: {g} vs {w}");
        }
        let handovers = deployment.leaders_total("handovers");
        let moved = deployment.leaders_total("sets_sent");
        assert!(
            handovers > 0 && moved > 0,
            "{what}: {handovers} handovers, {moved} moved"
        );
        eprintln!("{what}: {handovers} handover items, {moved} components moved");
    }
}

/// Leaders push their sums at each fresh cut and the coordinator answers
/// from the pushes; with every second push lost on purpose, the queries
/// that miss one ask the leaders instead, and every answer is still the
/// centralized engine's to 1e-9.
#[test]
fn answers_pushed_at_a_cut_or_lost_and_asked_for_change_no_answer() {
    let dir = std::env::temp_dir().join(format!("idmesh-factored-pushed-{}", std::process::id()));
    let trace = crowd(&dir, 12, 4, 60.0, 7);
    let central = central(&trace);
    let truths = truth_lines(&trace);
    for (name, drop_push_every) in [("pushed", None), ("pushes-lost", Some(2))] {
        let settings = Settings {
            leader_faults: LeaderFaultSection {
                drop_push_every,
                ..LeaderFaultSection::default()
            },
            ..settings(4, false)
        };
        let deployment = Deployment::start(name, &trace, &settings);
        deployment.first_answer(Duration::from_secs(30));
        check_points(name, &deployment, &truths, &central);
        let (pushed, asked) = (
            deployment.coordinator_counter("cuts_pushed"),
            deployment.coordinator_counter("cuts_asked"),
        );
        eprintln!("{name}: {pushed} cuts answered from pushes, {asked} asked for");
        match drop_push_every {
            None => assert!(
                pushed > 0 && asked * 10 <= pushed,
                "{name}: {pushed} pushed, {asked} asked\n{}",
                deployment.log()
            ),
            Some(_) => assert!(
                asked > 0,
                "{name}: {pushed} pushed, {asked} asked\n{}",
                deployment.log()
            ),
        }
    }
}

fn matrix(v: &Value) -> Vec<Vec<f64>> {
    v.as_array()
        .unwrap_or_else(|| panic!("a matrix: {v}"))
        .iter()
        .map(floats)
        .collect()
}

/// A stream of colours and identities under the factored belief, through
/// three leaders, one of them killed mid-stream and restarted from its
/// journal and snapshot: the leaders hold components for the colours and
/// the information matrix's rows for the identities, side by side. The
/// final colour answer equals `idmesh replay --method factored` of the
/// same trace, the final identity answer `idmesh replay --method
/// information-matrix`, both to 1e-9; every row is held once.
#[test]
fn colours_and_identities_under_the_factored_belief_survive_a_leader_crash() {
    colours_and_identities_through_a_crash(false);
}

/// The same with the killed leader's role adopted by another process,
/// from the journal and snapshot, rows included.
#[test]
fn colours_and_identities_under_the_factored_belief_survive_a_takeover() {
    colours_and_identities_through_a_crash(true);
}

fn colours_and_identities_through_a_crash(adopted: bool) {
    let dir = std::env::temp_dir().join(format!(
        "idmesh-factored-ids-{adopted}-{}",
        std::process::id()
    ));
    let trace = crowd_with_identities(&dir, 12, 4, 90.0, 5);
    let colours = central(&trace);
    // The Radon belief (what such a stream held before) answers otherwise
    // here: an answer equal to the factored replay's is the factored
    // belief's.
    let radon = replay_lines(&trace, &["--method", "overcomplete"]);
    let gap = floats(&radon.last().unwrap()["p_red"])
        .iter()
        .zip(floats(&colours.last().unwrap()["p_red"]))
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(gap > 1e-6, "the factored and Radon replays agree: {gap}");
    let identities = replay_lines(&trace, &["--method", "information-matrix"]);
    let settings = Settings {
        leaders: 3,
        rate: Some(500.0),
        journal: true,
        snapshot_every: Some(40),
        // Restarted (no adoption however slow), or adopted soon.
        takeover_after_ms: Some(if adopted { 1000 } else { 0 }),
        factored: Some(belief(true)),
        window: Some(WINDOW),
        ..Settings::default()
    };
    let name = format!("factored-identities-{adopted}");
    let mut crashed = Deployment::start_each(&name, &trace, &settings);
    let first = crashed.first_answer(Duration::from_secs(30));
    assert_eq!(first["finished"], false, "the stream has begun, not ended");
    std::thread::sleep(Duration::from_millis(300));
    crashed.kill("leader-1");
    if !adopted {
        std::thread::sleep(Duration::from_millis(500));
        crashed.launch("leader", "leader-1");
    }

    let last = crashed.final_marginals(Duration::from_secs(60));
    let want = floats(&colours.last().unwrap()["p_red"]);
    for (t, (g, w)) in floats(&last["p_red"]).iter().zip(&want).enumerate() {
        assert!((g - w).abs() < 1e-9, "colours, track {t}: {g} vs {w}");
    }
    let answer = crashed.answer_when(&["identity"], Duration::from_secs(60), |a| {
        a["finished"] == true
    });
    let want = identities.last().unwrap();
    let (got, wanted) = (matrix(&answer["p_identity"]), matrix(&want["p_identity"]));
    assert_eq!(got.len(), wanted.len());
    for (t, (g, w)) in got.iter().zip(&wanted).enumerate() {
        let off = g
            .iter()
            .zip(w)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(off < 1e-9, "identities, track {t}: off by {off}");
    }
    assert_eq!(answer["predicted_identity"], want["predicted_identity"]);

    // Components and rows both moved between leaders, and leader-1 came
    // back from its journal with its rows.
    assert_eq!(
        crashed.leaders_total("rows_held"),
        12,
        "every row held once"
    );
    let handovers = crashed.leaders_total("handovers");
    let moved = crashed.leaders_total("sets_sent");
    assert!(
        handovers > 0 && moved > 0,
        "{handovers} handovers, {moved} components moved"
    );
    let role = crashed.leader("leader-1");
    assert!(role["recoveries"].as_u64().unwrap() > 0);
    assert_eq!(
        role["host"] != "leader-1",
        adopted,
        "leader-1's role is hosted by {}",
        role["host"]
    );
}
