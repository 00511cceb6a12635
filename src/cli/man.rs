//! `dmdsl man [COMMAND]`: a man page (roff), on stdout.

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
    let mut out = Vec::new();
    clap_mangen::Man::new(cmd).render(&mut out)?;
    use std::io::Write;
    std::io::stdout().write_all(&out)?;
    Ok(0)
}
