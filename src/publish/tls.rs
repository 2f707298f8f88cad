//! The TLS client configuration of the station's links (`mqtts://`): rustls with the ring
//! provider, the broker's certificate verified against the configured CA file or the
//! system's certificate authorities.
//!
//! Layer 4 (process edge): depends on rustls, rustls-pemfile and rustls-native-certs; reads
//! the CA file.

use rustls::pki_types::CertificateDer;
use std::path::Path;
use std::sync::Arc;

/// The certificates in a PEM text (anything else in it is skipped).
pub fn certificates(pem: &[u8]) -> Vec<CertificateDer<'static>> {
    rustls_pemfile::certs(&mut &pem[..])
        .filter_map(Result::ok)
        .collect()
}

/// A client configuration that trusts `ca_file`'s certificates, or the system's when none
/// is given.
pub fn client_config(ca_file: Option<&Path>) -> Result<Arc<rustls::ClientConfig>, String> {
    let mut roots = rustls::RootCertStore::empty();
    match ca_file {
        Some(p) => {
            let pem = std::fs::read(p).map_err(|e| format!("cannot read {}: {e}", p.display()))?;
            for c in certificates(&pem) {
                roots
                    .add(c)
                    .map_err(|e| format!("{}: a certificate is unusable: {e}", p.display()))?;
            }
        }
        None => {
            let found = rustls_native_certs::load_native_certs();
            let (added, _) = roots.add_parsable_certificates(found.certs);
            if added == 0 {
                return Err("the system has no CA certificates (install the Debian package ca-certificates, or set [mqtt] ca-file)".into());
            }
        }
    }
    // ring rather than aws-lc-rs: no cmake and no C++ toolchain on a station build. rustls
    // marks it deprecated because ring has no post-quantum key exchange; the classical
    // groups it offers are what lab brokers (Mosquitto, EMQX, HiveMQ) negotiate today.
    #[allow(deprecated)]
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let config = rustls::ClientConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()
        .map_err(|e| format!("TLS: {e}"))?
        .with_root_certificates(roots)
        .with_no_client_auth();
    Ok(Arc::new(config))
}
