//! The documentation says what the build does: messages quoted in docs/EXIT_CODES.md, the
//! README's demo scheme, and `--help` texts whose shown form is the accepted form (issue 17 item 11).

use std::path::PathBuf;
use std::process::Command;

const CBD: &str = env!("CARGO_BIN_EXE_cbd");

fn repo_file(name: &str) -> String {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..").join(name);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// EXIT_CODES.md once said "this build reads 1" when the build read 2 (now 2 to 4).
#[test]
fn exit_codes_version_message_is_what_this_build_prints() {
    let found = cbd_protocol::FORMAT_VERSION + 1;
    let message = cbd_protocol::DecodeError::UnsupportedVersion { found, supported: cbd_protocol::FORMAT_VERSION }.to_string();
    let reads = &message[message.find("(this build reads").expect("message names what the build reads")..];
    let docs = repo_file("docs/EXIT_CODES.md");
    assert!(docs.contains(reads), "docs/EXIT_CODES.md does not quote {reads:?}");
}

/// The README once said the demo fits Heun × 5; `cbd demo --hyperparameters paper` fits Euler × 2
/// (asked of the command itself, on a small grid, not read from its source).
#[test]
fn readme_demo_scheme_is_what_demo_fits() {
    let readme = repo_file("README.md");
    assert!(!readme.contains("Heun × 5"), "README still says Heun × 5");
    let dir = std::env::temp_dir().join(format!("cbd-docs-demo-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (blob, json) = (dir.join("paper.blob"), dir.join("paper.json"));
    let out = Command::new(CBD)
        .args(["demo", "--quiet", "--hyperparameters", "paper", "--grid", "4", "--test-points", "10", "--out"])
        .arg(&blob)
        .arg("--json")
        .arg(&json)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let report: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    assert_eq!(
        (report["integrator"].as_str(), report["steps"].as_u64()),
        (Some("euler"), Some(2)),
        "the paper reproduction's scheme changed: update the README"
    );
    assert!(readme.contains("`--hyperparameters paper` reproduces the paper's kernels"));
    assert!(readme.contains("with Euler × 2."));
}

/// `cbd bench --help` showed `--sizes`' default space-separated ("64 256 1024 4096"), a form the
/// flag rejects: the help must show the comma-separated form it accepts.
#[test]
fn bench_help_shows_sizes_as_accepted() {
    let out = Command::new(CBD).args(["bench", "--help"]).output().unwrap();
    let help = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success());
    assert!(help.contains("[default: 64,256,1024,4096]"), "{help}");
    assert!(help.contains("[default: 256,4096]"), "{help}");
    assert!(!help.contains("64 256"), "{help}");
}

/// Issue 39: the compensation guide (docs/guide/compensate.md) and EXIT_CODES.md say what each of `cbd compensate`'s flags
/// means; every flag the build writes is named in both.
#[test]
fn every_compensate_flag_is_documented() {
    use cbd_trainer::evaluation::command_check::RowFlags;
    let none = RowFlags::default();
    let each = [
        RowFlags { not_reached: true, ..none },
        RowFlags { outside_limits: true, ..none },
        RowFlags { degenerate_target: true, ..none },
        RowFlags { singular: true, ..none },
        RowFlags { extrapolating: true, ..none },
    ];
    let (readme, codes) = (repo_file("docs/guide/compensate.md"), repo_file("docs/EXIT_CODES.md"));
    for flag in each.iter().map(RowFlags::text).chain(std::iter::once(none.text())) {
        assert!(readme.contains(&format!("`{flag}`")), "docs/guide/compensate.md does not name `{flag}`");
        if flag != "ok" {
            assert!(codes.contains(&format!("`{flag}`")), "docs/EXIT_CODES.md does not name `{flag}`");
        }
    }
}
