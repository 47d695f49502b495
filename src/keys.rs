//! API keys: generation, hashing, constant-time verification, scopes.
//!
//! A key looks like `gw_<id>_<secret>`: `id` (16 lowercase hex digits) names the key in the
//! store and in logs; `secret` (32 random bytes, base64url) is shown once, when the key is
//! created, and only `SHA-256(secret)` is stored. The secret carries 256 bits of entropy, so a
//! plain (unsalted) SHA-256 is enough — there is nothing to brute-force — and the stored hash is
//! compared in constant time ([`subtle`]) so response timing says nothing about it.
//!
//! Webhook payloads are signed with [`sign_webhook`]: `HMAC-SHA256(secret, "<t>.<body>")`,
//! sent as `Gearwear-Signature: t=<unix seconds>,v1=<hex>`.

use base64::Engine;
use hmac::{KeyInit, Mac};
use sha2::{Digest, Sha256};
use subtle::ConstantTimeEq;

pub use gearwear_store::keys::{Scope, grants};

/// A freshly generated key: the full token (shown once) and what gets stored.
#[derive(Debug, Clone)]
pub struct NewKey {
    pub id: String,
    pub token: String,
    pub hash: String,
}

/// Generate a new random key.
pub fn generate() -> NewKey {
    let mut idb = [0u8; 8];
    let mut secret = [0u8; 32];
    rand::fill(&mut idb[..]);
    rand::fill(&mut secret[..]);
    let id = hex::encode(idb);
    let secret = base64::engine::general_purpose::URL_SAFE_NO_PAD.encode(secret);
    let hash = hash_secret(&secret);
    NewKey {
        token: format!("gw_{id}_{secret}"),
        id,
        hash,
    }
}

/// Hex SHA-256 of a key's secret part.
pub fn hash_secret(secret: &str) -> String {
    hex::encode(Sha256::digest(secret.as_bytes()))
}

/// Split a presented token into `(id, secret)`; `None` if it is not shaped like a key.
pub fn split_token(token: &str) -> Option<(&str, &str)> {
    let rest = token.strip_prefix("gw_")?;
    let (id, secret) = rest.split_once('_')?;
    let id_ok = id.len() == 16 && id.bytes().all(|b| b.is_ascii_hexdigit());
    (id_ok && !secret.is_empty() && secret.len() <= 128).then_some((id, secret))
}

/// Constant-time comparison of a presented secret against a stored hash: both sides are
/// 64 hex digits (the length is public), compared with [`subtle::ConstantTimeEq`], which
/// looks at every byte whatever the first difference.
pub fn verify(secret: &str, stored_hash: &str) -> bool {
    let h = hash_secret(secret);
    h.as_bytes().ct_eq(stored_hash.as_bytes()).into()
}

/// The webhook signature header value for `body` sent at unix time `t` (seconds).
pub fn sign_webhook(secret: &str, t: i64, body: &[u8]) -> String {
    format!("t={t},v1={}", webhook_mac(secret, t, body))
}

/// Hex `HMAC-SHA256(secret, "<t>." + body)`.
pub fn webhook_mac(secret: &str, t: i64, body: &[u8]) -> String {
    let mut mac =
        hmac::Hmac::<Sha256>::new_from_slice(secret.as_bytes()).expect("HMAC takes any key length");
    mac.update(format!("{t}.").as_bytes());
    mac.update(body);
    hex::encode(mac.finalize().into_bytes())
}

/// A random webhook signing secret (`whsec_` + 32 bytes base64url).
pub fn webhook_secret() -> String {
    let mut b = [0u8; 32];
    rand::fill(&mut b[..]);
    format!(
        "whsec_{}",
        base64::engine::general_purpose::URL_SAFE_NO_PAD.encode(b)
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn token_round_trip_and_verification() {
        let k = generate();
        let (id, secret) = split_token(&k.token).unwrap();
        assert_eq!(id, k.id);
        assert!(verify(secret, &k.hash));
        assert!(!verify("nope", &k.hash));
        assert!(split_token("Bearer x").is_none());
        assert!(split_token("gw_zz_abc").is_none());
    }

    #[test]
    fn verify_accepts_the_secret_and_rejects_a_near_miss() {
        let k = generate();
        let (_, secret) = split_token(&k.token).unwrap();
        assert!(verify(secret, &k.hash));
        // The same secret with only its last byte changed.
        let mut near = secret.as_bytes().to_vec();
        let last = near.len() - 1;
        near[last] = if near[last] == b'A' { b'B' } else { b'A' };
        let near = String::from_utf8(near).unwrap();
        assert_ne!(near, secret);
        assert!(!verify(&near, &k.hash));
        // A prefix, an extension, the stored hash itself and the empty string: all refused.
        assert!(!verify(&secret[..secret.len() - 1], &k.hash));
        assert!(!verify(&format!("{secret}A"), &k.hash));
        assert!(!verify(&k.hash, &k.hash));
        assert!(!verify("", &k.hash));
        // What is stored is the SHA-256, never the secret.
        assert_ne!(k.hash, secret);
        assert!(!k.hash.contains(secret));
        assert_eq!(k.hash.len(), 64);
    }

    #[test]
    fn scopes_parse_and_admin_grants_all() {
        assert_eq!(
            Scope::parse_list("read, ingest,read").unwrap(),
            vec![Scope::Ingest, Scope::Read]
        );
        assert_eq!(Scope::parse_list("read,write"), Err("write".into()));
        assert!(grants(&[Scope::Admin], Scope::Ingest));
        assert!(!grants(&[Scope::Read], Scope::Ingest));
    }

    #[test]
    fn webhook_signature_matches_a_known_vector() {
        let mac = webhook_mac("Jefe", 0, b"what do ya want for nothing?");
        // Independent value: HMAC-SHA256("Jefe", "0.what do ya want for nothing?") computed by
        // Python's hmac module.
        assert_eq!(
            mac,
            "37f471929915ccd2cbbe79feb84ffcff4f2bb25e15fc41c2506687331ae179cc"
        );
        assert_eq!(
            sign_webhook("Jefe", 0, b"what do ya want for nothing?"),
            format!("t=0,v1={mac}")
        );
    }
}
