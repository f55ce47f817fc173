//! `shoal summarize`: summary.json and the plots from a recording alone.

use std::path::PathBuf;

use crate::pipeline;

/// Arguments of `shoal summarize`.
#[derive(Debug, clap::Args)]
#[command(after_help = "\
From the recording alone: safety, formation, perception, mission, the MPC, the
end-to-end latency, the events and the wall time of the run. The processes'
runtime figures come from their last recorded statistics (about once a
simulated second); CPU time and peak memory are not in a recording and are
left empty. A recording cut short (Ctrl-C, SIGKILL) is read up to its last
complete chunk; `shoal recover` writes a whole copy first if you want one.")]
pub struct SummarizeCmd {
    /// The recording (MCAP written by `shoal run`).
    pub recording: PathBuf,
    /// Where summary.json and plots/ go (default: beside the recording).
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Replace the summary.json and plots/ already in DIR.
    #[arg(long)]
    pub force: bool,
    /// No closing table.
    #[arg(long, short)]
    pub quiet: bool,
}

/// Runs `shoal summarize`.
pub fn run(cmd: SummarizeCmd) -> anyhow::Result<()> {
    let out = match cmd.out {
        Some(d) => d,
        None => cmd
            .recording
            .parent()
            .map_or_else(|| PathBuf::from("."), PathBuf::from),
    };
    let out = if out.as_os_str().is_empty() {
        PathBuf::from(".")
    } else {
        out
    };
    // What a summary writes; the recording beside them is never touched.
    let outputs = ["summary.json", "plots", "report.html"].map(|n| out.join(n));
    if let Some(there) = outputs.iter().find(|p| p.exists()) {
        if !cmd.force {
            anyhow::bail!(
                "{} exists: pass --force to replace summary.json, plots/ and report.html, or choose --out (nothing was written)",
                there.display()
            );
        }
        for p in &outputs {
            let gone = if p.is_dir() {
                std::fs::remove_dir_all(p)
            } else {
                std::fs::remove_file(p)
            };
            if let Err(e) = gone {
                if e.kind() != std::io::ErrorKind::NotFound {
                    return Err(
                        anyhow::Error::new(e).context(format!("cannot remove {}", p.display()))
                    );
                }
            }
        }
    }
    let s = pipeline::summarize_into(&cmd.recording, &out)?;
    if !cmd.quiet {
        super::run::print_table(&s);
    }
    println!("{}", out.display());
    Ok(())
}
