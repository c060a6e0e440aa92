//! `idmesh acoustic`: the acoustic front end (the `idmesh-acoustic` crate) behind a
//! command line — the field of the paper's Section VI, the separation and
//! tracking pipeline, and the recovered paths written as a trace (`move`
//! lines, and `mix` lines where two recovered paths come close), with a
//! progress bar on stderr and the paper's metrics at the end.

use crate::cli::AcousticArgs;
use anyhow::{Context, Result};
use idmesh_acoustic::write_trace;
use idmesh_acoustic::PathSpec;
use idmesh_acoustic::{run as track, AcousticConfig};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::fs::File;
use std::io::BufWriter;

pub fn run(args: &AcousticArgs) -> Result<()> {
    let mut config = AcousticConfig::paper(args.sensors, args.targets, args.seed);
    if args.zigzag {
        // Fig. 15: 300 m between the ends, 100 m wide, two periods.
        config.field.paths = PathSpec::Zigzag {
            periods: 2,
            length: 300.0,
            width: 100.0,
        };
    }
    let bar = ProgressBar::with_draw_target(Some(0), ProgressDrawTarget::stderr());
    bar.set_style(
        ProgressStyle::with_template("{spinner} tracking [{bar:40}] {percent:>3}% ({eta})")
            .context("progress bar template")?
            .progress_chars("=> "),
    );
    let result = track(&config, &mut |done, total| {
        bar.set_length(total);
        bar.set_position(done);
    })
    .context("acoustic tracking failed")?;
    bar.finish_and_clear();
    let path = args.out.display().to_string();
    let file = File::create(&args.out).with_context(|| format!("{path}: cannot create"))?;
    write_trace(&result, BufWriter::new(file), path.clone())?;
    let m = &result.metrics;
    eprintln!(
        "{path}: {} targets heard by {} sensors; mean error {:.1} m (sd {:.1} m), coverage {:.0}%",
        args.targets,
        args.sensors,
        m.mean_error,
        m.std_error,
        100.0 * m.coverage
    );
    Ok(())
}
