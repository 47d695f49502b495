//! The binary: `keys create|list|revoke`, and `serve` refusing a non-loopback address
//! without keys.

use crate::helpers::{gearwear_bin, gearwear_ok};

#[test]
fn keys_are_printed_once_and_stored_hashed() {
    let dir = std::env::temp_dir().join(format!("gearwear-cli-{}", uuid::Uuid::new_v4().simple()));
    std::fs::create_dir_all(&dir).unwrap();
    let db = dir.join("k.db");
    let db = db.to_str().unwrap();

    // No key yet: a non-loopback address is refused.
    let out = gearwear_bin()
        .args(["serve", "--address", "0.0.0.0:0", "--database-url", db])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("not a loopback address") && err.contains("keys create"),
        "{err}"
    );

    let token = gearwear_ok(&[
        "keys",
        "create",
        "--scope",
        "ingest,read",
        "--label",
        "daq-box",
        "--database-url",
        db,
    ]);
    let (id, secret) = gearwear::keys::split_token(&token).expect("a key");
    // The store holds the hash, never the secret.
    let bytes = std::fs::read(dir.join("k.db")).unwrap();
    let wal = std::fs::read(dir.join("k.db-wal")).unwrap_or_default();
    for b in [&bytes, &wal] {
        assert!(
            !b.windows(secret.len()).any(|w| w == secret.as_bytes()),
            "secret in the file"
        );
    }

    let out = gearwear_bin()
        .args(["keys", "list", "--database-url", db])
        .output()
        .unwrap();
    let list = String::from_utf8(out.stdout).unwrap();
    assert!(
        list.contains(id) && list.contains("ingest,read") && list.contains("daq-box"),
        "{list}"
    );
    assert!(!list.contains(secret));

    let out = gearwear_bin()
        .args(["keys", "revoke", id, "--database-url", db])
        .output()
        .unwrap();
    assert!(out.status.success());
    let out = gearwear_bin()
        .args(["keys", "revoke", id, "--database-url", db])
        .output()
        .unwrap();
    assert!(!out.status.success(), "revoking twice says so");
    let out = gearwear_bin()
        .args(["keys", "create", "--scope", "write", "--database-url", db])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("unknown scope `write`"));
    let _ = std::fs::remove_dir_all(&dir);
}

/// With no database named, every subcommand opens the same file — `gearwear.db` under the
/// user's data directory (`$XDG_DATA_HOME/gearwear/`, else `~/.local/share/gearwear/`), made
/// when missing — whatever the current directory; `GEARWEAR_DATABASE_URL` wins over
/// `DATABASE_URL`, `--database-url` over both; `keys create` and `serve`'s start-up line name
/// the file. Run with a temporary HOME and XDG_DATA_HOME: the real home is not written to.
#[test]
fn every_subcommand_opens_the_same_default_database() {
    use std::io::{BufRead, BufReader};
    use std::path::Path;
    use std::process::{Output, Stdio};

    let root =
        std::env::temp_dir().join(format!("gearwear-home-{}", uuid::Uuid::new_v4().simple()));
    let (home, a, b) = (root.join("home"), root.join("a"), root.join("b"));
    for d in [&home, &a, &b] {
        std::fs::create_dir_all(d).unwrap();
    }
    let cmd = |cwd: &Path, envs: &[(&str, &Path)]| {
        let mut c = gearwear_bin();
        c.current_dir(cwd)
            .env("HOME", &home)
            .env_remove("XDG_DATA_HOME")
            .env_remove("GEARWEAR_DATABASE_URL")
            .env_remove("DATABASE_URL");
        for (k, v) in envs {
            c.env(k, v);
        }
        c
    };
    let run = |cwd: &Path, envs: &[(&str, &Path)], args: &[&str]| -> Output {
        let out = cmd(cwd, envs).args(args).output().unwrap();
        assert!(
            out.status.success(),
            "gearwear {args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        out
    };
    let stderr = |o: &Output| String::from_utf8_lossy(&o.stderr).into_owned();

    // The default: made under HOME, found from another directory by every subcommand.
    let default = home.join(".local/share/gearwear/gearwear.db");
    let made = run(&a, &[], &["keys", "create", "--scope", "read"]);
    assert!(default.is_file(), "{}", stderr(&made));
    let shown = default.display().to_string();
    assert!(stderr(&made).contains(&shown), "{}", stderr(&made));
    let token = String::from_utf8(made.stdout).unwrap();
    let (id, _) = gearwear::keys::split_token(token.trim()).unwrap();
    let list = run(&b, &[], &["keys", "list"]);
    assert!(String::from_utf8_lossy(&list.stdout).contains(id));
    run(&b, &[], &["machine", "set", "m1", "--input-shaft-hz", "30"]);
    let gearboxes = run(&a, &[], &["gearbox", "list"]);
    assert!(
        String::from_utf8_lossy(&gearboxes.stdout)
            .trim_start()
            .starts_with('[')
    );
    let gone = run(&a, &[], &["machine", "delete", "m1"]);
    assert!(stderr(&gone).contains(&shown), "{}", stderr(&gone));
    assert!(!a.join("gearwear.db").exists() && !b.join("gearwear.db").exists());

    // XDG_DATA_HOME, when set, is the data directory.
    let xdg = root.join("xdg");
    run(&a, &[("XDG_DATA_HOME", &xdg)], &["keys", "list"]);
    assert!(xdg.join("gearwear/gearwear.db").is_file());

    // The product's variable, then the generic one, then the flag over both.
    let (g, d, f) = (root.join("g.db"), root.join("d.db"), root.join("f.db"));
    let both: [(&str, &Path); 2] = [("GEARWEAR_DATABASE_URL", &g), ("DATABASE_URL", &d)];
    run(&a, &both, &["keys", "list"]);
    assert!(g.is_file() && !d.exists());
    run(&a, &both[1..], &["keys", "list"]);
    assert!(d.is_file());
    run(
        &a,
        &both,
        &["keys", "list", "--database-url", f.to_str().unwrap()],
    );
    assert!(f.is_file());

    // A gearwear.db in the current directory (the old default) is pointed out, not used.
    std::fs::write(b.join("gearwear.db"), b"").unwrap();
    let noted = run(&b, &[], &["keys", "list"]);
    assert!(
        stderr(&noted).contains("--database-url gearwear.db"),
        "{}",
        stderr(&noted)
    );
    assert_eq!(std::fs::metadata(b.join("gearwear.db")).unwrap().len(), 0);

    // serve names the database in its start-up line.
    let mut child = cmd(Path::new(env!("CARGO_MANIFEST_DIR")), &[])
        .args(["serve", "--address", "127.0.0.1:0"])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut seen = String::new();
    for line in BufReader::new(child.stderr.take().unwrap()).lines() {
        let line = line.unwrap();
        seen.push_str(&line);
        seen.push('\n');
        if line.contains("API keys and machines live in") {
            break;
        }
    }
    let _ = child.kill();
    let _ = child.wait();
    let start = seen
        .lines()
        .find(|l| l.contains("API keys and machines live in"))
        .unwrap_or_else(|| panic!("no start-up line: {seen}"));
    assert!(start.contains(&format!("live in {shown}")), "{start}");
    let _ = std::fs::remove_dir_all(&root);
}
