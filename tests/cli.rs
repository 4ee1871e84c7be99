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

#[test]
fn optimize_waveform_writes_a_resumable_run_and_a_driver_fragment() {
    let dir = std::env::temp_dir().join(format!("nm-cli-opt-{}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    let cfg = dir.join("tiny.yaml");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(
        &cfg,
        "objective: model\namplitude_v: 24.0\nseed: 3\nsimulation: {warmup_cycles: 1, cycles: 1}\nbudget:\n  sa: {chunks: 2, iterations: 10}\n  pso: {chunks: 1, iterations: 1, particles: 3}\n  local: {chunks: 1, iterations: 10}\n",
    )
    .unwrap();
    let run = |budget: &str| {
        out(nm()
            .arg("optimize-waveform")
            .arg(&cfg)
            .args(["--budget", budget, "--out"])
            .arg(&dir))
    };
    let (ok, stdout, stderr) = run("1");
    assert!(ok, "{stderr}");
    assert!(
        stdout.contains("asymmetric") && stdout.contains("simulated annealing"),
        "{stdout}"
    );
    let wf = std::fs::read_to_string(dir.join("waveform.yaml")).unwrap();
    assert!(wf.contains("kind: free") && wf.contains("points_v"), "{wf}");
    // The fragment is accepted by a driver block.
    let graph = format!(
        "base_rate_hz: 4000\nduration_s: 0.05\nblocks:\n  - name: fa\n    type: constant\n    value: 14.0\n  - name: driver\n    type: walking_piezo_driver\n{}connections:\n  - {{ from: fa.y, to: driver.f_alpha }}\nlog: [driver.u]\n",
        wf.lines()
            .filter(|l| !l.starts_with('#'))
            .map(|l| format!("    {l}\n"))
            .collect::<String>()
    );
    let g = dir.join("graph.yaml");
    std::fs::write(&g, graph).unwrap();
    let (ok, _, stderr) = out(nm().arg("check").arg(&g));
    assert!(ok, "{stderr}");
    // Running again resumes the finished run file: the same waveform, bit for bit.
    let (ok, _, stderr) = run("1");
    assert!(ok && stderr.contains("resuming"), "{stderr}");
    assert_eq!(
        std::fs::read_to_string(dir.join("waveform.yaml")).unwrap(),
        wf
    );
    // Another budget is another run: refused, naming the fix.
    let (ok, _, stderr) = run("2");
    assert!(!ok && stderr.contains("another configuration"), "{stderr}");
    // Bad input names the field.
    let (ok, _, stderr) = run("0");
    assert!(!ok && stderr.contains("--budget"), "{stderr}");
    std::fs::write(&cfg, "objective: model\nf_alpha_hz: .nan\n").unwrap();
    let (ok, _, stderr) = run("1");
    assert!(
        !ok && stderr.contains("f_alpha_hz") && stderr.contains(":2:1"),
        "{stderr}"
    );
    std::fs::remove_dir_all(&dir).ok();
}
