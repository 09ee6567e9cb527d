//! Issue 48: the README's tests were red on a cloud server whose sysfs reports its host's 480 MiB
//! L3 — faer's multiply reserved twice that per thread, so a 16-row diagnose needed 1.1 GB, `cbd
//! fit` refused 256 rows under 512 MB and `cbd plan` aborted. Here the commands run on such a host
//! for real: a private mount namespace puts a copy of `/sys/devices/system/cpu` that reports a
//! 480 MiB L3 in place of the real one (both faer's multiply and the memory check read it there),
//! under a 512 MB address-space limit, and in a cgroup with a 512 MB memory limit. Needs root and
//! `unshare` (CI runs as root); elsewhere each test says why it did not run.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use crate::cli_support;

const CBD: &str = env!("CARGO_BIN_EXE_cbd");

fn scratch(name: &str) -> PathBuf {
    cli_support::scratch(&format!("large-cache-{name}"))
}

/// A sysfs CPU folder for two CPUs with a 48 KiB L1, a 2 MiB L2 each and a shared 480 MiB L3.
fn server_sysfs(dir: &Path) -> PathBuf {
    let root = dir.join("cpu");
    for cpu in 0..2 {
        let caches = [
            (1, "Data", "48K", cpu.to_string(), 12),
            (2, "Unified", "2048K", cpu.to_string(), 16),
            (3, "Unified", "491520K", "0-1".into(), 16),
        ];
        for (k, (level, kind, size, shared, ways)) in caches.into_iter().enumerate() {
            let index = root.join(format!("cpu{cpu}/cache/index{k}"));
            std::fs::create_dir_all(&index).unwrap();
            for (name, text) in [
                ("level", level.to_string()),
                ("type", kind.to_string()),
                ("size", size.to_string()),
                ("shared_cpu_list", shared),
                ("ways_of_associativity", ways.to_string()),
                ("coherency_line_size", "64".into()),
            ] {
                std::fs::write(index.join(name), text).unwrap();
            }
        }
    }
    root
}

/// Runs `script` (sh) with `$CBD` set, in a mount namespace whose CPU sysfs is `sysfs`; `None`
/// when this machine cannot make one (not root, no `unshare`).
fn on_server(sysfs: &Path, dir: &Path, script: &str) -> Option<Output> {
    let probe = Command::new("unshare").args(["-m", "true"]).output().ok()?;
    if !probe.status.success() {
        return None;
    }
    let full = format!("mount --bind '{}' /sys/devices/system/cpu || exit 90\n{script}", sysfs.display());
    Some(Command::new("unshare").args(["-m", "sh", "-c", &full]).env("CBD", CBD).current_dir(dir).output().unwrap())
}

fn text(o: &Output) -> String {
    format!("exit {:?}\nstdout:\n{}\nstderr:\n{}", o.status.code(), String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

/// Six-joint data for the UR5 example's model: 16 and 256 rows.
fn six_joint_data(dir: &Path) {
    for (rows, seed) in [(16, "3"), (256, "4")] {
        let out = Command::new(CBD)
            .args(["simulate", "--robot", "six", "--sampling", "uniform", "--count", &rows.to_string(), "--seed", seed, "--out"])
            .arg(dir.join(format!("six{rows}.csv")))
            .output()
            .unwrap();
        assert!(out.status.success(), "{}", text(&out));
    }
}

const UR5: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../examples/ur5/ur5.toml");

/// What the commands of the issue run, each line `name exit-code`.
fn commands() -> String {
    format!(
        r#"
"$CBD" diagnose --model {UR5} --data six16.csv --no-cbd --json d16.json >d16.log 2>&1; echo "diagnose-no-cbd $?"
"$CBD" diagnose --model {UR5} --data six16.csv --json d16b.json >d16b.log 2>&1; echo "diagnose $?"
"$CBD" fit --model {UR5} --data six256.csv --out f256.blob --json f256.json >f256.log 2>&1; echo "fit $?"
"$CBD" plan --model {UR5} --count 3 --candidates 200 --workspace 16 --out plan.csv >plan.log 2>&1; echo "plan $?"
"#
    )
}

fn exit_codes(o: &Output) -> Vec<(String, i32)> {
    String::from_utf8_lossy(&o.stdout)
        .lines()
        .filter_map(|l| l.rsplit_once(' ').and_then(|(name, code)| Some((name.to_string(), code.parse().ok()?))))
        .collect()
}

#[test]
fn small_problems_run_under_512_mb_of_address_space_on_a_480_mib_l3_host() {
    let dir = scratch("ulimit");
    let sysfs = server_sysfs(&dir);
    six_joint_data(&dir);
    // The host really looks like the server from inside (what faer's multiply reads).
    let Some(seen) = on_server(&sysfs, &dir, "cat /sys/devices/system/cpu/cpu0/cache/index2/size") else {
        eprintln!("skipped: no mount namespace here (needs root and unshare)");
        return;
    };
    assert_eq!(String::from_utf8_lossy(&seen.stdout).trim(), "491520K", "{}", text(&seen));
    let out = on_server(&sysfs, &dir, &format!("ulimit -v 512000\n{}", commands())).unwrap();
    let codes = exit_codes(&out);
    assert_eq!(codes.len(), 4, "{}", text(&out));
    for (name, code) in codes {
        let log = std::fs::read_to_string(dir.join(match name.as_str() {
            "diagnose-no-cbd" => "d16.log",
            "diagnose" => "d16b.log",
            "fit" => "f256.log",
            _ => "plan.log",
        }))
        .unwrap_or_default();
        assert_eq!(code, 0, "{name} under 512 MB of address space on a 480 MiB-L3 host:\n{log}");
    }
    // The fit says what it needed, and its peak address space is within 2× of that.
    let report: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join("f256.json")).unwrap()).unwrap();
    let (estimated, peak) =
        (report["memory"]["estimated_bytes"].as_f64().unwrap(), report["memory"]["peak_address_space_bytes"].as_f64().unwrap());
    assert!(peak <= 2.0 * estimated && estimated <= 2.0 * peak, "estimated {estimated}, peak address space {peak}");
}

/// This process's cgroup v1 memory folder, when the memory controller is mounted there (v1 or hybrid).
fn own_memory_cgroup() -> Option<PathBuf> {
    let text = std::fs::read_to_string("/proc/self/cgroup").ok()?;
    let path = text.lines().find_map(|l| {
        let mut f = l.splitn(3, ':');
        let (_, controllers, path) = (f.next()?, f.next()?, f.next()?);
        controllers.split(',').any(|c| c == "memory").then(|| path.to_string())
    })?;
    let dir = Path::new("/sys/fs/cgroup/memory").join(path.trim_start_matches('/'));
    dir.join("memory.limit_in_bytes").exists().then_some(dir)
}

/// This process's cgroup v2 folder, when memory is a controller its children may use.
fn own_unified_cgroup() -> Option<PathBuf> {
    let text = std::fs::read_to_string("/proc/self/cgroup").ok()?;
    let path = text.lines().find_map(|l| l.strip_prefix("0::"))?;
    let dir = Path::new("/sys/fs/cgroup").join(path.trim_start_matches('/'));
    let controllers = std::fs::read_to_string(dir.join("cgroup.subtree_control")).ok()?;
    controllers.split_whitespace().any(|c| c == "memory").then_some(dir)
}

#[test]
fn small_problems_run_in_a_512_mb_cgroup_and_large_ones_are_refused() {
    let dir = scratch("cgroup");
    let sysfs = server_sysfs(&dir);
    six_joint_data(&dir);
    let name = format!("cbd-test-{}", std::process::id());
    let (group, limit_file) = match (own_memory_cgroup(), own_unified_cgroup()) {
        (Some(v1), _) => (v1.join(&name), "memory.limit_in_bytes"),
        (None, Some(v2)) => (v2.join(&name), "memory.max"),
        _ => {
            eprintln!("skipped: no cgroup memory controller this test may use");
            return;
        }
    };
    if std::fs::create_dir(&group).is_err() || std::fs::write(group.join(limit_file), "512000000").is_err() {
        eprintln!("skipped: cannot make a cgroup with a memory limit here (needs root)");
        let _ = std::fs::remove_dir(&group);
        return;
    }
    // A 4096-row six-joint fit in the kernel form needs (12288)² × 4 values: refused up front.
    let big = Command::new(CBD)
        .args(["simulate", "--robot", "six", "--sampling", "uniform", "--count", "4096", "--seed", "5", "--out"])
        .arg(dir.join("six4096.csv"))
        .output()
        .unwrap();
    assert!(big.status.success(), "{}", text(&big));
    let script = format!(
        "echo $$ > '{}/cgroup.procs' || exit 91\n{}\"$CBD\" fit --model {UR5} --data six4096.csv --representation kernel --out big.blob >big.log 2>&1; echo \"big $?\"\n",
        group.display(),
        commands()
    );
    let out = on_server(&sysfs, &dir, &script);
    let _ = std::fs::remove_dir(&group);
    let Some(out) = out else {
        eprintln!("skipped: no mount namespace here (needs root and unshare)");
        return;
    };
    let codes = exit_codes(&out);
    assert_eq!(codes.len(), 5, "{}", text(&out));
    for (name, code) in &codes[..4] {
        assert_eq!(*code, 0, "{name} in a 512 MB cgroup on a 480 MiB-L3 host: {}", text(&out));
    }
    let log = std::fs::read_to_string(dir.join("big.log")).unwrap();
    assert_eq!(codes[4].1, 1, "a fit too large for the cgroup is refused (exit 1), not killed:\n{log}");
    assert!(log.contains("more than the") && log.contains("MB this process may use"), "{log}");
}
