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
