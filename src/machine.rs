//! The machine a figure was measured on, for the provenance lines of `bench` and `report`:
//! its CPU model, its cores and the threads used, and its memory bandwidth as a short copy
//! measures it. Machines of one kind differ by 2x here (the same binary's drop-3d 300^3 step
//! took 7.2 s on one 2-core machine and 3.3 s on another); a figure from a bandwidth-bound
//! stage is read beside the bandwidth it had.

use std::sync::LazyLock;
use std::time::Instant;

/// Bytes of each buffer the copy test moves: twice the last-level cache these machines report
/// (32 MiB of L3), so the copy runs from memory.
const COPY_BYTES: usize = 64 << 20;

/// Copies timed; the fastest counts (the others pay for page faults and neighbours).
const COPY_REPEATS: usize = 4;

/// The CPU's model name (`/proc/cpuinfo`).
pub fn cpu_model() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|t| {
            t.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split_once(':'))
                .map(|(_, v)| v.trim().to_string())
        })
        .unwrap_or_else(|| "an unknown CPU".into())
}

/// Memory bandwidth in GB/s as one thread's copy of [`COPY_BYTES`] measures it, the bytes read
/// and written counted (STREAM's "copy" convention). Measured once per process, in a few
/// hundredths of a second; its buffers are freed and the process's peak memory reset after it,
/// so that no run's peak counts them.
pub fn copy_bandwidth_gb_s() -> f64 {
    static MEASURED: LazyLock<f64> = LazyLock::new(|| {
        let n = COPY_BYTES / 8;
        let from: Vec<u64> = (0..n as u64).collect();
        let mut to = vec![0u64; n];
        let best = (0..COPY_REPEATS)
            .map(|_| {
                let t = Instant::now();
                to.copy_from_slice(std::hint::black_box(&from));
                std::hint::black_box(&to);
                t.elapsed().as_secs_f64()
            })
            .fold(f64::INFINITY, f64::min);
        drop((from, to));
        reset_peak_memory();
        2.0 * COPY_BYTES as f64 / best / 1e9
    });
    *MEASURED
}

/// Resets this process's peak resident memory (`VmHWM`) to its current size (Linux), so that
/// the next peak read is of what runs from now on. The allocator's free pages go back to the
/// kernel first: glibc keeps a freed heap resident, and a report's run after a larger one in
/// the same process read that as its own (the falling obstacle at 100 x 150 x 100 after
/// drop-3d at 150^3: 763 MiB, against 451 alone; 2026-11-29, 8cb4dd1).
pub fn reset_peak_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: `malloc_trim` only hands the allocator's free pages back to the kernel.
    unsafe {
        libc::malloc_trim(0);
    }
    let _ = std::fs::write("/proc/self/clear_refs", "5");
}

/// A machine as the figures made on it depend on: its CPU, its cores, the worker threads the
/// figures were made with, and its memory copy bandwidth.
#[derive(Clone, Debug, PartialEq)]
pub struct Machine {
    /// The CPU's model name ([`cpu_model`]).
    pub cpu: String,
    pub cores: usize,
    pub threads: usize,
    /// [`copy_bandwidth_gb_s`], GB/s.
    pub copy_gb_s: f64,
}

impl Machine {
    /// This machine, with `threads` the worker threads the figures are made with.
    pub fn here(threads: usize) -> Self {
        Self {
            cpu: cpu_model(),
            cores: std::thread::available_parallelism().map_or(0, |n| n.get()),
            threads,
            copy_gb_s: copy_bandwidth_gb_s(),
        }
    }

    /// The machine in one phrase with its bandwidth as `gb_s` says it (one figure, or the
    /// range of several machines of this kind): `AMD EPYC 7B13 (2 cores, 2 threads, memory
    /// copy 11.2 GB/s)`.
    pub fn with_bandwidth(&self, gb_s: &str) -> String {
        self.described(&format!(", memory copy {gb_s} GB/s"))
    }

    /// The kind of machine, without the bandwidth that moves from run to run: `AMD EPYC 7B13
    /// (2 cores, 2 threads)`. Timings compare between runs of one kind (report.csv's `machine`).
    pub fn kind(&self) -> String {
        self.described("")
    }

    /// The CPU with its cores and threads in brackets, and `more` within them.
    fn described(&self, more: &str) -> String {
        let (cores, threads) = (count(self.cores, "core"), count(self.threads, "thread"));
        format!("{} ({cores}, {threads}{more})", self.cpu)
    }
}

/// `n` things, `thing` in the plural but for one.
pub fn count(n: usize, thing: &str) -> String {
    format!("{n} {thing}{}", if n == 1 { "" } else { "s" })
}

/// The machine in one phrase ([`Machine::with_bandwidth`], to a tenth of a GB/s).
impl std::fmt::Display for Machine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.with_bandwidth(&format!("{:.1}", self.copy_gb_s)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_machine_line_names_a_cpu_and_a_plausible_bandwidth() {
        let line = Machine::here(2).to_string();
        assert!(
            line.contains("2 threads") && line.contains("GB/s"),
            "{line}"
        );
        let one = Machine::here(1).to_string();
        assert!(one.contains(" 1 thread,"), "{one}");
        // Anything a machine of ours can do: DDR memory copies at 1 to 1000 GB/s.
        let bw = copy_bandwidth_gb_s();
        assert!((1.0..1000.0).contains(&bw), "{bw} GB/s");
    }
}
