//! The text after each command's `--help` options: examples, then the exit codes as they
//! apply to that command (each command file keeps its own exit-code text).

/// After `dmdsl --help`.
pub(crate) const TOP: &str = "Examples:
  dmdsl slice part.stl                     # writes part.dmdjob/ (masks + job.json)
  dmdsl run part.dmdjob                    # dry run: verify masks, replay on a simulated machine
  dmdsl profile list                       # the built-in machine profiles
  dmdsl completions bash > ~/.local/share/bash-completion/completions/dmdsl";

/// The exit codes of every command, after `dmdsl --help`.
pub(crate) const TOP_EXIT: &str = "Exit codes (each command's --help says what they mean for it):
  0    success
  1    finished, but checks failed (denied warnings, run violations)
  2    usage or input error
  130  interrupted (Ctrl-C, SIGTERM or SIGHUP)";

/// After `dmdsl slice --help`, before its exit codes.
pub(crate) const SLICE: &str = "Examples:
  dmdsl slice part.stl                                  # part.dmdjob, default profile
  dmdsl slice part.stl -p bottom-up --layer-height 0.1 -o job.dmdjob
  dmdsl slice part.stl -o part.sl1                      # one file: .dmdjob.zip, .sl1, .sl1s
  dmdsl slice part.stl --json --deny-warnings > summary.json   # CI: exit 1 on a warning";

/// After `dmdsl run --help`, before its exit codes.
pub(crate) const RUN: &str = "Examples:
  dmdsl run part.dmdjob                                 # summary; exit 1 on any violation
  dmdsl run part.dmdjob --json > report.json
  dmdsl run part.dmdjob --trace t.csv --plot p.png --layers 10..20 --fault stall@12
  dmdsl run part.sl1        # also part.dmdjob.zip, .sl1s, an SLA control-file .zip";

/// After `dmdsl calibrate --help`, before its exit codes.
pub(crate) const CALIBRATE: &str = "Examples:
  dmdsl calibrate readings.csv -o cal.toml               # fit, plots beside cal.toml
  dmdsl calibrate readings.csv -o cal.toml --relative    # meter in arbitrary units
  dmdsl calibrate readings.csv -o cal.toml --json --no-plots
  dmdsl slice part.stl --calibration cal.toml            # then compensate a job with it";

/// After `dmdsl distortion --help`, before its exit codes.
pub(crate) const DISTORTION: &str = "Examples:
  dmdsl distortion lens.csv                             # fit report
  dmdsl distortion lens.csv --plot correction.png
  dmdsl distortion lens.csv --json
  dmdsl slice part.stl --distortion lens.csv             # pre-warp a job's masks with it";

/// After `dmdsl profile --help`.
pub(crate) const PROFILE: &str = "Examples:
  dmdsl profile list                                    # name and description of each
  dmdsl profile show bottom-up > mine.toml              # a commented profile to edit
  dmdsl slice part.stl -p mine.toml                     # then slice with it

Exit codes:
  0    printed
  2    unknown profile name, unreadable or invalid profile file";

/// After `dmdsl completions --help`.
pub(crate) const COMPLETIONS: &str = "Examples:
  dmdsl completions bash > ~/.local/share/bash-completion/completions/dmdsl
  dmdsl completions zsh > ~/.zfunc/_dmdsl       # with fpath+=(~/.zfunc) in ~/.zshrc
  dmdsl completions fish > ~/.config/fish/completions/dmdsl.fish

Exit codes:
  0    the script was written to stdout
  2    usage error (unknown shell)";

/// After `dmdsl man --help`.
pub(crate) const MAN: &str = "Examples:
  dmdsl man > dmdsl.1 && man ./dmdsl.1                  # the overview page
  dmdsl man slice > dmdsl-slice.1                       # one command's page
  sudo sh -c 'dmdsl man > /usr/local/share/man/man1/dmdsl.1'

Exit codes:
  0    the page was written to stdout
  2    usage error (unknown command)";

/// `examples`, a blank line, then `exit`.
pub(crate) fn join(examples: &str, exit: &str) -> String {
    format!("{examples}\n\n{exit}")
}
