//! HTTPS for the page: the certificate chain and key of `[web] tls-cert` / `tls-key` (PEM)
//! made into a rustls server configuration (ring's cryptography, TLS 1.2 and 1.3, HTTP/1.1).
//!
//! Layer 4 (process edge): depends on rustls (through tokio-rustls) and rustls-pki-types;
//! reads the two files once, at start.

use rustls_pki_types::pem::PemObject;
use rustls_pki_types::{CertificateDer, PrivateKeyDer};
use std::path::Path;
use std::sync::Arc;
use tokio_rustls::rustls::{self, ServerConfig};
use tokio_rustls::TlsAcceptor;

/// The acceptor of `cert` and `key`; the error names the file and what to do.
pub fn acceptor(cert: &Path, key: &Path) -> Result<TlsAcceptor, String> {
    let certs: Vec<CertificateDer<'static>> = CertificateDer::pem_file_iter(cert)
        .and_then(|it| it.collect::<Result<_, _>>())
        .map_err(|e| {
            format!(
                "web.tls-cert: cannot read a PEM certificate chain from {}: {e}",
                cert.display()
            )
        })?;
    if certs.is_empty() {
        return Err(format!(
            "web.tls-cert: {} holds no certificate (-----BEGIN CERTIFICATE-----)",
            cert.display()
        ));
    }
    let key = PrivateKeyDer::from_pem_file(key).map_err(|e| {
        format!(
            "web.tls-key: cannot read a PEM private key from {}: {e}",
            key.display()
        )
    })?;
    // rustls marks its ring provider deprecated for lacking post-quantum key exchange, which
    // only its aws-lc-rs provider has; that one needs cmake and a long C build on every
    // station, and the page's traffic (a station's status and commands on the lab network)
    // does not call for it.
    #[allow(deprecated)]
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let mut config = ServerConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()
        .map_err(|e| format!("TLS: {e}"))?
        .with_no_client_auth()
        .with_single_cert(certs, key)
        .map_err(|e| {
            format!("web.tls-cert / web.tls-key: the key does not go with the certificate, or one of them is not usable: {e}")
        })?;
    config.alpn_protocols = vec![b"http/1.1".to_vec()];
    Ok(TlsAcceptor::from(Arc::new(config)))
}
