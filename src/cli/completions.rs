//! `dmdsl completions SHELL`: the shell's completion script, on stdout.
//!
//! Besides what the parser declares (commands, options, `--format` names), the script offers
//! the built-in profile names wherever a profile is taken (`-p/--profile`, `--machine`,
//! `profile show`; for the options bash offers file names beside them, as a profile may be
//! a TOML file) and every `-W CODE=ACTION` rule (each warning code, each area and `all`,
//! with each action).

use clap::builder::PossibleValuesParser;
use clap::{Arg, Args, Command, CommandFactory};

#[derive(Args)]
pub(crate) struct CompletionsArgs {
    /// The shell to complete in.
    shell: clap_complete::Shell,
}

/// Ids of the arguments that take a machine profile (a built-in name or a TOML file).
const PROFILE_ARGS: [&str; 3] = ["profile", "machine", "name"];

/// Every `-W` rule: each code, area and `all` with each action (strings that live as long
/// as the process, which writes one script).
fn warning_rules() -> Vec<&'static str> {
    let mut targets: Vec<&str> = vec!["all"];
    for c in crate::warning::CODES {
        let area = c.code.split_once('.').map_or(c.code, |(a, _)| a);
        if !targets.contains(&area) {
            targets.push(area);
        }
    }
    targets.extend(crate::warning::CODES.iter().map(|c| c.code));
    targets
        .iter()
        .flat_map(|t| ["error", "warn", "allow"].map(|a| format!("{t}={a}")))
        .map(|r| &*Box::leak(r.into_boxed_str()))
        .collect()
}

/// `arg` with `values` as its possible values, for the completion script only (the parser
/// that reads the command line keeps its own rules).
fn offering(arg: Arg, values: &[&'static str]) -> Arg {
    arg.value_parser(PossibleValuesParser::new(values.to_vec()))
}

/// `cmd` and its subcommands with the profile names and warning rules as possible values.
fn with_values(cmd: Command, profiles: &[&'static str], rules: &[&'static str]) -> Command {
    let is_profile_show = cmd.get_name() == "show";
    let cmd = cmd.mut_args(|a| {
        let id = a.get_id().as_str();
        if id == "warn" {
            offering(a, rules)
        } else if PROFILE_ARGS.contains(&id) && (id != "name" || is_profile_show) {
            offering(a, profiles)
        } else {
            a
        }
    });
    let names: Vec<String> = cmd
        .get_subcommands()
        .map(|s| s.get_name().to_owned())
        .collect();
    names.into_iter().fold(cmd, |cmd, n| {
        cmd.mut_subcommand(n, |s| with_values(s, profiles, rules))
    })
}

/// The completion script for `shell`.
pub(crate) fn script(shell: clap_complete::Shell) -> String {
    let profiles = crate::profile::builtin_names();
    let mut cmd = with_values(super::Cli::command(), &profiles, &warning_rules());
    let mut out = Vec::new();
    clap_complete::generate(shell, &mut cmd, "dmdsl", &mut out);
    let text = String::from_utf8(out).expect("clap_complete writes UTF-8");
    if shell != clap_complete::Shell::Bash {
        return text;
    }
    // bash: a profile may also be a file, so its words come with the file names.
    let words = format!("compgen -W \"{}\" -- \"${{cur}}\")", profiles.join(" "));
    let with_files = format!(
        "compgen -W \"{}\" -- \"${{cur}}\") $(compgen -f -- \"${{cur}}\")",
        profiles.join(" ")
    );
    text.replace(&words, &with_files)
}

/// Runs `dmdsl completions`.
pub(crate) fn completions(a: CompletionsArgs) -> anyhow::Result<u8> {
    use std::io::Write;
    std::io::stdout().write_all(script(a.shell).as_bytes())?;
    Ok(0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap_complete::Shell;

    #[test]
    fn scripts_offer_profiles_formats_and_warning_rules() {
        for shell in [Shell::Bash, Shell::Zsh, Shell::Fish] {
            let s = script(shell);
            for name in crate::profile::builtin_names() {
                assert!(s.contains(name), "{shell}: profile {name}");
            }
            for want in [
                "sla-control",
                "plan.wait-capped=allow",
                "mesh=error",
                "all=warn",
            ] {
                assert!(s.contains(want), "{shell}: {want}");
            }
        }
        let bash = script(Shell::Bash);
        assert!(
            bash.contains("$(compgen -f -- \"${cur}\")"),
            "bash: profile files"
        );
    }
}
