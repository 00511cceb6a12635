//! The `dmdsl` command line: parses arguments, calls the library, maps errors to exit codes.
//!
//! Exit codes: 0 success; 1 finished, but checks failed (e.g. `slice --strict` on a
//! defective mesh); 2 usage or input error; 130 interrupted.

use anyhow::Context as _;
use clap::{Args, Parser, Subcommand};
use dmdsl::job::{self, PlacementMode, SliceOptions};
use dmdsl::profile::{self, Profile};
use dmdsl::units::Positive;
use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

const EXIT_HELP: &str = "Exit codes:
  0    success
  1    finished, but checks failed (slice --strict with mesh defects)
  2    usage or input error (bad file, bad profile, part does not fit)
  130  interrupted (Ctrl-C); nothing was written";

/// Build-job compiler for DMD mask-projection stereolithography.
#[derive(Parser)]
#[command(name = "dmdsl", version, about, after_help = EXIT_HELP)]
struct Cli {
    /// Print nothing but errors.
    #[arg(short, long, global = true)]
    quiet: bool,
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Slice a part (STL or OBJ) into a job bundle of mask PNGs and a manifest.
    #[command(after_help = EXIT_HELP)]
    Slice(SliceArgs),
    /// Show or list machine profiles.
    #[command(subcommand)]
    Profile(ProfileCmd),
}

#[derive(Args)]
struct SliceArgs {
    /// The part: binary or ASCII STL, or OBJ.
    input: PathBuf,
    /// Bundle to write (default: <input stem>.dmdjob in the current directory).
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// Machine profile: a built-in name or a TOML file.
    #[arg(short, long, default_value = profile::DEFAULT_PROFILE)]
    profile: String,
    /// Layer height in mm (default: the profile's).
    #[arg(long, value_name = "MM")]
    layer_height: Option<f64>,
    /// Binary masks: a pixel is lit when its centre is inside the section.
    #[arg(long)]
    binary: bool,
    /// Use the file's coordinates as build-plane coordinates instead of centring the part.
    #[arg(long)]
    keep_position: bool,
    /// Exit with code 1 if the mesh has defects (the bundle is still written).
    #[arg(long)]
    strict: bool,
    /// Print a machine-readable summary on stdout.
    #[arg(long)]
    json: bool,
}

#[derive(Subcommand)]
enum ProfileCmd {
    /// Print a profile as TOML (built-in: with its comments), ready to copy and edit.
    Show {
        /// Built-in name or TOML file.
        name: String,
    },
    /// List the built-in profiles.
    List,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(code) => ExitCode::from(code),
        Err(e) => {
            let code = e
                .downcast_ref::<dmdsl::Error>()
                .map(|d| d.exit_code())
                .unwrap_or(2);
            eprintln!("dmdsl: error: {e:#}");
            ExitCode::from(code as u8)
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<u8> {
    match cli.cmd {
        Cmd::Slice(a) => slice(a, cli.quiet),
        Cmd::Profile(ProfileCmd::List) => {
            for (name, src) in profile::BUILTIN {
                let p = Profile::from_toml(src, name)?;
                println!("{name}\t{}", p.description);
            }
            Ok(0)
        }
        Cmd::Profile(ProfileCmd::Show { name }) => {
            match profile::builtin_source(&name) {
                Some(src) => print!("{src}"),
                None => print!("{}", Profile::resolve(&name)?.to_toml()),
            }
            Ok(0)
        }
    }
}

fn slice(a: SliceArgs, quiet: bool) -> anyhow::Result<u8> {
    let profile = Profile::resolve(&a.profile)?;
    let layer_height_mm = match a.layer_height {
        None => None,
        Some(v) => Some(Positive::new(v).ok_or_else(|| {
            dmdsl::Error::Usage(format!("--layer-height must be a number > 0, got {v}"))
        })?),
    };
    let cancel = Arc::new(AtomicBool::new(false));
    {
        let c = cancel.clone();
        // A second handler registration fails only if one exists; ignore that.
        let _ = ctrlc::set_handler(move || c.store(true, Ordering::Relaxed));
    }
    let show_progress = !quiet && !a.json && std::io::stderr().is_terminal();
    let progress = |done: usize, total: usize| {
        if done == total || done % 16 == 0 {
            let mut e = std::io::stderr().lock();
            let _ = write!(e, "\rslicing: layer {done}/{total}");
            if done == total {
                let _ = writeln!(e);
            }
        }
    };
    let opts = SliceOptions {
        input: a.input.clone(),
        output: a.output.clone(),
        profile,
        layer_height_mm,
        binary: a.binary.then_some(true),
        placement: if a.keep_position {
            PlacementMode::Keep
        } else {
            PlacementMode::Center
        },
        progress: if show_progress { Some(&progress) } else { None },
        cancel: Some(&cancel),
    };
    let summary = job::slice_to_bundle(&opts)
        .with_context(|| format!("slice {} failed", a.input.display()))
        .map_err(|e| match e.downcast::<dmdsl::Error>() {
            // Keep the library's one-line message (it already names the file).
            Ok(d) => anyhow::Error::new(d),
            Err(e) => e,
        })?;
    let defects = !summary.mesh.closed_manifold;
    let failed = a.strict && defects;
    if a.json {
        let v = serde_json::json!({
            "bundle": summary.bundle,
            "layers": summary.layers,
            "warnings": summary.warnings,
            "mesh": summary.mesh,
            "totals": summary.totals,
            "timings": summary.timings,
            "checks_failed": failed,
        });
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else if !quiet {
        for w in &summary.warnings {
            eprintln!("dmdsl: warning: {w}");
        }
        println!(
            "{}: {} layers, {:.1} mm, est. print time {}, {:.2} ml resin ({:.2} s)",
            summary.bundle.display(),
            summary.layers,
            summary.totals.height_mm,
            hms(summary.totals.print_time_s),
            summary.totals.resin_volume_ml,
            summary.timings.total_s
        );
        if let (Some(all), Some(c)) = (
            summary.totals.all_layered_time_s,
            summary.totals.continuous_layers,
        ) {
            println!(
                "hybrid: {c} of {} layers continuous; all layered would take {} ({:.0} % saved)",
                summary.layers,
                hms(all),
                100.0 * (1.0 - summary.totals.print_time_s / all)
            );
        }
    }
    if failed {
        if !quiet {
            eprintln!("dmdsl: --strict: mesh has defects (see warnings); exit code 1");
        }
        return Ok(1);
    }
    Ok(0)
}

fn hms(s: f64) -> String {
    let s = s.round() as u64;
    format!("{}h{:02}m{:02}s", s / 3600, s / 60 % 60, s % 60)
}
