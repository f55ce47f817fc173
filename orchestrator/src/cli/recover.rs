//! `shoal recover`: rewrites a truncated recording as a complete, indexed MCAP.

use std::path::PathBuf;

use anyhow::Context;

/// Arguments of `shoal recover`.
#[derive(Debug, clap::Args)]
pub struct RecoverCmd {
    /// The recording whose writer died (SIGKILL, power loss: no summary or
    /// footer, a last chunk cut short). It is read up to its last complete
    /// chunk; the copy gets a summary and indexes, so every MCAP reader
    /// opens it. Prints how many messages were saved and how many bytes
    /// were dropped.
    pub recording: PathBuf,
    /// Where to write the complete copy (default: REC.recovered.mcap). An
    /// existing file is never overwritten.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

/// Runs `shoal recover`.
pub fn run(cmd: RecoverCmd) -> anyhow::Result<()> {
    let out = cmd
        .out
        .clone()
        .unwrap_or_else(|| cmd.recording.with_extension("recovered.mcap"));
    let r = recordings::recover(&cmd.recording, &out)
        .with_context(|| format!("recovering {}", cmd.recording.display()))?;
    if cmd.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
        return Ok(());
    }
    if r.input_truncated {
        println!(
            "{}: truncated after byte {} of {}{}",
            r.input,
            r.kept_bytes,
            r.input_bytes,
            r.stop_reason
                .as_deref()
                .map(|s| format!(" ({s})"))
                .unwrap_or_default()
        );
    } else {
        println!("{}: complete; copied as is", r.input);
    }
    println!(
        "saved {} messages ({} channels, {} schemas, {} metadata, {} chunks); dropped {} bytes",
        r.messages, r.channels, r.schemas, r.metadata, r.chunks, r.dropped_bytes
    );
    println!("{}", r.output);
    Ok(())
}
