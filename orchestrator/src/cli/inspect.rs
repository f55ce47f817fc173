//! `shoal inspect`: a recording's channels, counts, rates and gaps.

use std::path::PathBuf;

/// Prints the report of the recording at `path` as a table or JSON, with
/// its digest if asked.
pub fn run(path: PathBuf, json: bool, digest: bool) -> anyhow::Result<()> {
    let rec = recordings::Recording::open(&path)?;
    let report = rec.inspect();
    let digest = digest.then(|| rec.digest());
    if json {
        let mut v = serde_json::to_value(&report)?;
        if let (Some(d), Some(obj)) = (&digest, v.as_object_mut()) {
            obj.insert("digest".into(), d.clone().into());
        }
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(());
    }
    println!(
        "{}: {} messages, {:.3} s .. {:.3} s{}",
        report.path,
        report.messages,
        report.start_s,
        report.end_s,
        if report.truncated {
            "  [TRUNCATED: read up to the last complete chunk]"
        } else {
            ""
        }
    );
    println!(
        "{:<26} {:<20} {:>8} {:>9} {:>6} {:>9}",
        "topic", "schema", "count", "rate Hz", "gaps", "max gap s"
    );
    for c in &report.channels {
        println!(
            "{:<26} {:<20} {:>8} {:>9.2} {:>6} {:>9.3}",
            c.topic, c.schema, c.messages, c.rate_hz, c.gaps, c.max_interval_s
        );
    }
    if let Some(m) = report.metadata.get("shoal.run") {
        println!(
            "run: scenario {} seed {} mode {}",
            m.get("scenario").map_or("?", String::as_str),
            m.get("seed").map_or("?", String::as_str),
            m.get("mode").map_or("?", String::as_str)
        );
    }
    if let Some(d) = digest {
        println!("digest: {d}");
    }
    Ok(())
}
