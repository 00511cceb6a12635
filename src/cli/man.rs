//! `dmdsl man [COMMAND]`: a man page (roff), on stdout.
//!
//! clap_mangen renders the name, synopsis, description, options and commands; the text
//! `--help` shows after the options (examples, exit codes, notes) becomes sections of their
//! own (EXAMPLES, EXIT STATUS, NOTES), set without filling or justification so each example
//! stays one line as in `--help`.

use clap::{Args, CommandFactory};

#[derive(Args)]
pub(crate) struct ManArgs {
    /// The command whose page to write (dmdsl-COMMAND(1)); without it, the overview page
    /// dmdsl(1), which lists the commands.
    command: Option<String>,
}

/// Runs `dmdsl man`.
pub(crate) fn man(a: ManArgs) -> anyhow::Result<u8> {
    let top = super::Cli::command();
    let cmd = match &a.command {
        None => top,
        Some(name) => {
            let names: Vec<&str> = top.get_subcommands().map(|c| c.get_name()).collect();
            let sub = top.find_subcommand(name).ok_or_else(|| {
                crate::Error::Usage(format!(
                    "man {name}: no such command (commands: {})",
                    names.join(", ")
                ))
            })?;
            // The page is dmdsl-NAME(1); a process writes one page, so the name may live on.
            let page: &'static str = Box::leak(format!("dmdsl-{name}").into_boxed_str());
            sub.clone()
                .name(page)
                .bin_name(format!("dmdsl {name}"))
                .version(env!("CARGO_PKG_VERSION"))
        }
    };
    let out = page(cmd)?;
    use std::io::Write;
    std::io::stdout().write_all(&out)?;
    Ok(0)
}

/// The man page of `cmd`.
fn page(cmd: clap::Command) -> std::io::Result<Vec<u8>> {
    let mut cmd = cmd.disable_help_subcommand(true);
    cmd.build();
    let after = cmd.get_after_help().map(|h| h.to_string());
    let man = clap_mangen::Man::new(cmd.clone());
    let mut out = Vec::new();
    man.render_title(&mut out)?;
    man.render_name_section(&mut out)?;
    man.render_synopsis_section(&mut out)?;
    man.render_description_section(&mut out)?;
    if cmd.get_arguments().any(|a| !a.is_hide_set()) {
        man.render_options_section(&mut out)?;
    }
    if cmd.has_subcommands() {
        man.render_subcommands_section(&mut out)?;
    }
    if let Some(text) = after {
        out.extend_from_slice(sections(&text).as_bytes());
    }
    man.render_version_section(&mut out)?;
    Ok(out)
}

/// The text after `--help`'s options as roff sections: each paragraph headed "Examples:"
/// or "Exit codes ...:" a section of that name, any other paragraph a NOTES section; the
/// lines kept as they are (no fill).
fn sections(text: &str) -> String {
    let mut out = String::new();
    for para in text.split("\n\n") {
        let (first, rest) = para.split_once('\n').unwrap_or((para, ""));
        let (title, body) = if first.starts_with("Examples") {
            ("EXAMPLES", rest)
        } else if first.starts_with("Exit codes") {
            ("EXIT STATUS", rest)
        } else {
            ("NOTES", para)
        };
        out.push_str(&format!(".SH \"{title}\"\n.nf\n"));
        for line in body.lines() {
            out.push_str(&roff_line(line));
            out.push('\n');
        }
        out.push_str(".fi\n");
    }
    out
}

/// `line` as roff text: backslashes and hyphens escaped, a leading `.` or `'` guarded.
fn roff_line(line: &str) -> String {
    let escaped = line.replace('\\', "\\e").replace('-', "\\-");
    if escaped.starts_with(['.', '\'']) {
        format!("\\&{escaped}")
    } else {
        escaped
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn after_help_becomes_examples_and_exit_status_without_fill() {
        let text =
            "Examples:\n  dmdsl slice a.stl -o b   # one\n\nExit codes:\n  0    ok\n\n.x \\ y";
        let s = sections(text);
        assert_eq!(
            s,
            ".SH \"EXAMPLES\"\n.nf\n  dmdsl slice a.stl \\-o b   # one\n.fi\n\
             .SH \"EXIT STATUS\"\n.nf\n  0    ok\n.fi\n\
             .SH \"NOTES\"\n.nf\n\\&.x \\e y\n.fi\n"
        );
    }
}
