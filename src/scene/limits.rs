//! How much memory a run may still take: the smallest of the machine's available memory, the
//! limit of the control group the process runs in (a batch scheduler's `--mem`: Slurm confines
//! a job through the cgroup's `memory.max`) and the process's own resource limits (`ulimit -v`,
//! `ulimit -d`). A run is refused up front by the one that is smallest, named in the error,
//! rather than killed or aborted by it midway.

use std::path::{Path, PathBuf};

const GIB: f64 = (1u64 << 30) as f64;

/// A limit on the memory a run may still take.
#[derive(Clone, Debug, PartialEq)]
pub struct MemoryLimit {
    /// Bytes still free under it.
    pub bytes: f64,
    /// What sets it, as the error names it.
    pub source: String,
}

/// The smallest limit that applies to this process now, if any can be read.
pub fn smallest() -> Option<MemoryLimit> {
    let mut all = vec![];
    all.extend(meminfo());
    all.extend(cgroup_v2(Path::new("/sys/fs/cgroup")));
    all.extend(cgroup_v1(Path::new("/sys/fs/cgroup/memory")));
    all.extend(rlimits());
    all.into_iter().min_by(|a, b| a.bytes.total_cmp(&b.bytes))
}

/// `MemAvailable` of `/proc/meminfo`.
fn meminfo() -> Option<MemoryLimit> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    Some(MemoryLimit {
        bytes: kib_field(&text, "MemAvailable:")? * 1024.0,
        source: "the memory this machine has available (MemAvailable)".into(),
    })
}

/// The figure in KiB on the line of `text` that starts with `key`.
pub fn kib_field(text: &str, key: &str) -> Option<f64> {
    let line = text.lines().find(|l| l.starts_with(key))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

/// The process's cgroup path under the hierarchy `controller` names in `/proc/self/cgroup`
/// (`""` for the unified v2 hierarchy).
fn cgroup_path(controller: &str) -> Option<String> {
    let text = std::fs::read_to_string("/proc/self/cgroup").ok()?;
    cgroup_path_in(&text, controller)
}

/// [`cgroup_path`] from the text of a `/proc/PID/cgroup`.
fn cgroup_path_in(text: &str, controller: &str) -> Option<String> {
    text.lines().find_map(|l| {
        let mut f = l.splitn(3, ':');
        let (_, names, path) = (f.next()?, f.next()?, f.next()?);
        let found = match controller {
            "" => names.is_empty(),
            c => names.split(',').any(|n| n == c),
        };
        found.then(|| path.to_string())
    })
}

/// The folders of a cgroup and its ancestors under `root`, the cgroup's own first.
fn ancestry(root: &Path, path: &str) -> Vec<PathBuf> {
    let mut dirs = vec![root.to_path_buf()];
    for part in path.split('/').filter(|p| !p.is_empty() && *p != "..") {
        let next = dirs.last().expect("the root").join(part);
        dirs.push(next);
    }
    dirs.reverse();
    dirs
}

/// A number of bytes in a cgroup file, `None` for "max", a missing file or no limit.
fn bytes_in(dir: &Path, file: &str) -> Option<f64> {
    let text = std::fs::read_to_string(dir.join(file)).ok()?;
    let bytes: f64 = text.trim().parse().ok()?;
    // cgroup v1 writes "no limit" as the largest page-aligned i64.
    (bytes < 2f64.powi(62)).then_some(bytes)
}

/// The tightest `memory.max` of the v2 cgroup and its ancestors, less what the cgroup uses.
fn cgroup_v2(root: &Path) -> Option<MemoryLimit> {
    let path = cgroup_path("")?;
    tightest(root, &path, "memory.max", "memory.current", "cgroup v2")
}

/// The same for v1's memory controller: `memory.limit_in_bytes` less `memory.usage_in_bytes`.
fn cgroup_v1(root: &Path) -> Option<MemoryLimit> {
    let path = cgroup_path("memory")?;
    let (limit, usage) = ("memory.limit_in_bytes", "memory.usage_in_bytes");
    tightest(root, &path, limit, usage, "cgroup v1")
}

/// The smallest room left under the `limit` files of the cgroup at `path` and its ancestors.
fn tightest(root: &Path, path: &str, limit: &str, usage: &str, kind: &str) -> Option<MemoryLimit> {
    ancestry(root, path)
        .into_iter()
        .filter_map(|dir| {
            let max = bytes_in(&dir, limit)?;
            let used = bytes_in(&dir, usage).unwrap_or(0.0);
            Some(MemoryLimit {
                bytes: (max - used).max(0.0),
                source: format!(
                    "the memory limit of the control group ({kind} {}: {:.1} GiB, as a batch \
                     scheduler's --mem sets it)",
                    dir.join(limit).display(),
                    max / GIB
                ),
            })
        })
        .min_by(|a, b| a.bytes.total_cmp(&b.bytes))
}

/// `RLIMIT_AS` less the address space in use, and `RLIMIT_DATA` less the data segment.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn rlimits() -> Vec<MemoryLimit> {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let limits = [
        (libc::RLIMIT_AS, "VmSize:", "address space", "ulimit -v"),
        (libc::RLIMIT_DATA, "VmData:", "data segment", "ulimit -d"),
    ];
    limits
        .into_iter()
        .filter_map(|(resource, used, what, shell)| {
            let mut r = libc::rlimit {
                rlim_cur: 0,
                rlim_max: 0,
            };
            // SAFETY: getrlimit writes one rlimit through a valid pointer.
            let ok = unsafe { libc::getrlimit(resource, &mut r) } == 0;
            let limited = ok && r.rlim_cur != libc::RLIM_INFINITY;
            let max = limited.then_some(r.rlim_cur as f64)?;
            let in_use = kib_field(&status, used).unwrap_or(0.0) * 1024.0;
            Some(MemoryLimit {
                bytes: (max - in_use).max(0.0),
                source: format!("the process's {what} limit ({shell}: {:.1} GiB)", max / GIB),
            })
        })
        .collect()
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn rlimits() -> Vec<MemoryLimit> {
    vec![]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cgroup_paths_of_both_hierarchies_are_read() {
        let v1 = "12:pids:/user.slice\n4:memory:/slurm/uid_0/job_7\n0::/ignored\n";
        assert_eq!(
            cgroup_path_in(v1, "memory").as_deref(),
            Some("/slurm/uid_0/job_7")
        );
        assert_eq!(cgroup_path_in(v1, "").as_deref(), Some("/ignored"));
        let v2 = "0::/system.slice/slurmstepd.scope/job_3/step_batch\n";
        assert_eq!(cgroup_path_in(v2, "memory"), None);
        let dirs = ancestry(Path::new("/r"), "/a/b");
        assert_eq!(
            dirs,
            [Path::new("/r/a/b"), Path::new("/r/a"), Path::new("/r")]
        );
    }

    /// A job's cgroup under a parent with a looser limit: the job's room, less its usage, is
    /// the limit, named by its file; "max" and v1's "no limit" are none.
    #[test]
    fn the_tightest_cgroup_limit_less_its_usage_is_taken() {
        let root = std::env::temp_dir().join(format!("cellflip-cgroup-{}", std::process::id()));
        let job = root.join("slurm/job_1");
        std::fs::create_dir_all(&job).unwrap();
        std::fs::write(root.join("memory.max"), "max\n").unwrap();
        std::fs::write(root.join("slurm/memory.max"), "8589934592\n").unwrap();
        std::fs::write(job.join("memory.current"), "1073741824\n").unwrap();
        // The job's own limit, then none (v1's "no limit"): its parent's rules.
        for (job_max, room, named) in [
            ("2147483648", 1073741824.0, "job_1/memory.max: 2.0 GiB"),
            (
                "9223372036854771712",
                8589934592.0,
                "slurm/memory.max: 8.0 GiB",
            ),
        ] {
            std::fs::write(job.join("memory.max"), job_max).unwrap();
            let l = tightest(&root, "/slurm/job_1", "memory.max", "memory.current", "v2");
            let l = l.expect("a limit");
            assert_eq!(l.bytes, room);
            assert!(l.source.contains(named), "{}", l.source);
        }
        std::fs::remove_dir_all(&root).unwrap();
    }
}
