//! What a run folder records about the process that made it: CPU time and peak memory.

/// CPU seconds (user + system) this process has used so far, from `/proc/self/stat`; `None`
/// where that file does not exist (not Linux).
pub fn process_cpu_secs() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the parenthesised command name (which may hold spaces); utime and stime are
    // fields 14 and 15 of proc(5), in clock ticks of USER_HZ = 100 on Linux.
    let rest = &stat[stat.rfind(')')? + 2..];
    let fields: Vec<&str> = rest.split_ascii_whitespace().collect();
    let ticks = |i: usize| fields.get(i)?.parse::<f64>().ok();
    Some((ticks(11)? + ticks(12)?) / 100.0)
}

/// The largest resident memory of this process so far, bytes (`VmHWM` of `/proc/self/status`);
/// `None` where that file does not exist.
pub fn peak_rss_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: u64 = line.split_ascii_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cpu_time_grows_and_memory_is_plausible() {
        let (Some(before), Some(peak)) = (process_cpu_secs(), peak_rss_bytes()) else {
            eprintln!("skipped: no /proc on this system");
            return;
        };
        // Busy for about 0.3 s of CPU.
        let start = std::time::Instant::now();
        let mut x = 0u64;
        while start.elapsed().as_secs_f64() < 0.3 {
            x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(1));
        }
        let after = process_cpu_secs().unwrap();
        assert!(after - before > 0.1, "{before} → {after}");
        assert!(peak > 1 << 20 && peak < 1 << 40, "{peak}");
    }
}
