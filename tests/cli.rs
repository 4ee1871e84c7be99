//! The `nanomotion` binary as a user runs it.

use std::process::Command;

fn nm() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_nanomotion"));
    c.current_dir(env!("CARGO_MANIFEST_DIR"));
    c
}

fn out(c: &mut Command) -> (bool, String, String) {
    let o = c.output().expect("binary runs");
    (
        o.status.success(),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

#[test]
fn help_reads_well() {
    let (ok, stdout, _) = out(nm().arg("--help"));
    assert!(ok);
    for w in ["run", "check", "blocks", "Examples:", "quickstart.yaml"] {
        assert!(stdout.contains(w), "--help lacks `{w}`:\n{stdout}");
    }
}

#[test]
fn check_run_and_blocks() {
    let (ok, stdout, stderr) = out(nm().args(["check", "examples/quickstart.yaml"]));
    assert!(ok, "{stderr}");
    assert!(
        stdout.contains("ok") && stdout.contains("rate transitions inserted"),
        "{stdout}"
    );

    let dir = std::env::temp_dir().join(format!("nm-cli-{}", std::process::id()));
    let (ok, stdout, stderr) = out(nm()
        .args(["run", "examples/quickstart.yaml", "--out"])
        .arg(&dir));
    assert!(ok, "{stderr}");
    assert!(
        stdout.contains("true_err.y") && stdout.contains("rms"),
        "{stdout}"
    );
    for f in ["signals_40000hz.csv", "metrics.json", "cumulative_psd.svg"] {
        assert!(dir.join(f).exists(), "{f} not written");
    }
    std::fs::remove_dir_all(&dir).ok();

    let (ok, stdout, _) = out(nm().args(["blocks", "pid"]));
    assert!(ok);
    assert!(
        stdout.contains("pid (controller)") && stdout.contains("kp"),
        "{stdout}"
    );
}

#[test]
fn bad_graph_gives_an_error_not_a_panic() {
    let dir = std::env::temp_dir().join(format!("nm-cli-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let f = dir.join("bad.yaml");
    std::fs::write(
        &f,
        "base_rate_hz: 100\nduration_s: 1\nblocks:\n  - { name: a, type: gian, k: 1 }\n",
    )
    .unwrap();
    let (ok, _, stderr) = out(nm().arg("check").arg(&f));
    assert!(!ok);
    assert!(
        stderr.contains("error:") && stderr.contains("did you mean `gain`"),
        "{stderr}"
    );
    assert!(!stderr.contains("panicked"));
    let (ok, _, stderr) = out(nm().args(["run", "does/not/exist.yaml"]));
    assert!(!ok && stderr.contains("cannot read"), "{stderr}");
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn rc_check_reports_the_dvrc_criterion() {
    let (ok, stdout, stderr) = out(nm().args(["rc-check", "examples/rc_dvrc.yaml"]));
    assert!(ok, "{stdout}\n{stderr}");
    assert!(stdout.contains("5.9"), "{stdout}");
}
