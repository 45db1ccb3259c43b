//! What the benchmarks say about the process and the machine they ran on (included with
//! `#[path]`: each benchmark is its own crate).

/// The process's peak resident memory so far, MB (`VmHWM` of `/proc/self/status`); `None`
/// where the system does not say (not Linux).
pub fn peak_rss_mb() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

/// The machine's load averages over 1, 5 and 15 minutes (`/proc/loadavg`), or a sentence
/// saying they are unknown: a figure taken on a loaded machine is not comparable.
#[allow(dead_code)] // Not every benchmark that includes this module prints the load.
pub fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|s| {
            let parts: Vec<&str> = s.split_whitespace().take(3).collect();
            (parts.len() == 3).then(|| format!("{} (1, 5, 15 min)", parts.join(" ")))
        })
        .unwrap_or_else(|| "unknown (no /proc/loadavg)".to_string())
}
