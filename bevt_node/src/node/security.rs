//! DDS Security (SROS2): which enclave of which keystore the node's DDS participant uses,
//! decided at start-up exactly as ROS 2 (rcl + the rmw layers) decides it.
//!
//! - `ROS_SECURITY_ENABLE`: security is on only when it is exactly `true`.
//! - `ROS_SECURITY_STRATEGY`: `Enforce` (exactly) refuses to start when the enclave is not
//!   usable; anything else is *Permissive*: the node starts unsecured, with a warning.
//! - `ROS_SECURITY_KEYSTORE`: the keystore (as `ros2 security create_keystore` or
//!   `scripts/make-keystore.sh` makes it); unset or empty = no keystore.
//! - The enclave: `--ros-args --enclave /path` (or `-e`), default `/`;
//!   `ROS_SECURITY_ENCLAVE_OVERRIDE` replaces it when set. Its directory is
//!   `<keystore>/enclaves/<path>` and must hold the six files of [`ENCLAVE_FILES`].
//!
//! The node parameter `security_keystore` (parameters file or `-p`) does what
//! `ROS_SECURITY_ENABLE=true ROS_SECURITY_STRATEGY=Enforce ROS_SECURITY_KEYSTORE=...` do
//! together: a keystore written into the node's configuration is never silently ignored.
//!
//! A usable enclave gives [`DdsSecurity::Enclave`]; the DDS participant is then built with
//! RustDDS's built-in authentication, access-control and cryptographic plugins from its
//! files ([`crate::node::ros::context`]). Whether those files are *valid* (signatures,
//! certificate chain, a grant for the certificate's subject) is checked there, and a failure
//! stops start-up under either strategy, as in ROS 2.

use std::path::{Path, PathBuf};
use thiserror::Error;

/// `ROS_SECURITY_ENABLE`: security is on when this is exactly `true`.
pub const ENV_ENABLE: &str = "ROS_SECURITY_ENABLE";
/// `ROS_SECURITY_STRATEGY`: `Enforce` or (anything else) permissive.
pub const ENV_STRATEGY: &str = "ROS_SECURITY_STRATEGY";
/// `ROS_SECURITY_KEYSTORE`: the keystore directory.
pub const ENV_KEYSTORE: &str = "ROS_SECURITY_KEYSTORE";
/// `ROS_SECURITY_ENCLAVE_OVERRIDE`: an enclave path that replaces `--enclave`.
pub const ENV_ENCLAVE_OVERRIDE: &str = "ROS_SECURITY_ENCLAVE_OVERRIDE";

/// The files of an enclave directory (the names rmw_dds_common looks for).
pub const ENCLAVE_FILES: [&str; 6] = [
    "identity_ca.cert.pem",
    "cert.pem",
    "key.pem",
    "permissions_ca.cert.pem",
    "governance.p7s",
    "permissions.p7s",
];

/// Longest enclave path accepted, characters.
const MAX_ENCLAVE_CHARS: usize = 255;

/// What to do when security is requested but the enclave is not usable.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Strategy {
    /// Refuse to start.
    Enforce,
    /// Start unsecured, with a warning (ROS 2's default).
    #[default]
    Permissive,
}

/// The security request, as given by environment, arguments and parameters.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SecurityOptions {
    /// Security requested (`ROS_SECURITY_ENABLE=true`).
    pub enable: bool,
    /// Enforce or permissive.
    pub strategy: Strategy,
    /// The keystore, if any.
    pub keystore: Option<PathBuf>,
    /// The enclave path (`--enclave`, default `/`).
    pub enclave: String,
    /// `ROS_SECURITY_ENCLAVE_OVERRIDE`, if set and not empty.
    pub enclave_override: Option<String>,
}

impl Default for SecurityOptions {
    fn default() -> Self {
        Self {
            enable: false,
            strategy: Strategy::Permissive,
            keystore: None,
            enclave: "/".into(),
            enclave_override: None,
        }
    }
}

/// How the node's DDS participant is secured.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DdsSecurity {
    /// Unsecured, and why (for the start-up warning).
    Off {
        /// Why security is off.
        why: String,
    },
    /// Secured with the files of this enclave directory.
    Enclave(PathBuf),
}

impl Default for DdsSecurity {
    fn default() -> Self {
        Self::Off {
            why: format!("{ENV_ENABLE} is not \"true\""),
        }
    }
}

impl DdsSecurity {
    /// The start-up warning of an unsecured node (`None` when secured), naming what is
    /// exposed to every participant on `domain_id`.
    pub fn warning(&self, domain_id: u16) -> Option<String> {
        match self {
            Self::Enclave(_) => None,
            Self::Off { why } => Some(format!(
                "WARNING: DDS Security is off ({why}): the node is unauthenticated; any participant on domain {domain_id} can call reinit/stop, publish on init, read the tracks and list, read and set the node's parameters through the ROS parameter services (see docs/security.md)"
            )),
        }
    }
}

impl DdsSecurity {
    /// The line a program prints at start-up: the warning of an unsecured node, or the
    /// enclave of a secured one.
    pub fn startup_line(&self, domain_id: u16) -> String {
        match (self, self.warning(domain_id)) {
            (_, Some(w)) => w,
            (Self::Enclave(dir), None) => format!("DDS Security on, enclave {}", dir.display()),
            (Self::Off { why }, None) => why.clone(),
        }
    }
}

/// Security requested under `Enforce` but not usable: the node does not start.
#[derive(Debug, Error, PartialEq, Eq)]
#[non_exhaustive]
pub enum SecurityError {
    /// No keystore given.
    #[error("SECURITY ERROR (strategy Enforce): ROS_SECURITY_KEYSTORE is not set (and no security_keystore parameter)")]
    NoKeystore,
    /// The enclave path is not a valid ROS enclave name.
    #[error("SECURITY ERROR (strategy Enforce): enclave {0:?} is not a valid enclave path (absolute, `/`-separated names of letters, digits and `_`)")]
    BadEnclave(String),
    /// The enclave's directory does not exist.
    #[error("SECURITY ERROR (strategy Enforce): directory '{}' does not exist (enclave {enclave:?} of keystore '{}')", .dir.display(), .keystore.display())]
    NoEnclave {
        /// The enclave path.
        enclave: String,
        /// The keystore.
        keystore: PathBuf,
        /// The directory looked for.
        dir: PathBuf,
    },
    /// Files missing from the enclave directory.
    #[error("SECURITY ERROR (strategy Enforce): '{}' lacks {}", .dir.display(), .missing.join(", "))]
    MissingFiles {
        /// The enclave directory.
        dir: PathBuf,
        /// The files not found.
        missing: Vec<String>,
    },
    /// This build has no DDS Security.
    #[error("SECURITY ERROR (strategy Enforce): this bevt_node was built without the `security` cargo feature")]
    NotBuilt,
    /// The enclave's identity certificate or key is not usable now.
    #[error("SECURITY ERROR (strategy Enforce): {}: {reason}", .file.display())]
    BadIdentity {
        /// The certificate or key file.
        file: PathBuf,
        /// Why (expired, not yet valid, unreadable, the key does not match).
        reason: String,
    },
}

/// How every [`SecurityError`] message begins.
const ENFORCE_PREFIX: &str = "SECURITY ERROR (strategy Enforce): ";

impl SecurityOptions {
    /// The request from the environment (`env`) and the `--enclave` argument, as rcl reads
    /// it.
    pub fn from_env(env: impl Fn(&str) -> Option<String>, enclave: Option<String>) -> Self {
        Self {
            enable: env(ENV_ENABLE).as_deref() == Some("true"),
            strategy: if env(ENV_STRATEGY).as_deref() == Some("Enforce") {
                Strategy::Enforce
            } else {
                Strategy::Permissive
            },
            keystore: env(ENV_KEYSTORE)
                .filter(|s| !s.is_empty())
                .map(PathBuf::from),
            enclave: enclave.unwrap_or_else(|| "/".into()),
            enclave_override: env(ENV_ENCLAVE_OVERRIDE).filter(|s| !s.is_empty()),
        }
    }

    /// Decides how the participant is secured, looking at the file system.
    ///
    /// # Errors
    /// [`SecurityError`] when security is enabled with [`Strategy::Enforce`] and the
    /// enclave is not usable (under [`Strategy::Permissive`] that is
    /// [`DdsSecurity::Off`], with the reason).
    pub fn resolve(&self) -> Result<DdsSecurity, SecurityError> {
        if !self.enable {
            return Ok(DdsSecurity::default());
        }
        match self.find_enclave() {
            Ok(dir) => Ok(DdsSecurity::Enclave(dir)),
            Err(e) if self.strategy == Strategy::Permissive => Ok(DdsSecurity::Off {
                why: format!(
                    "security enabled, strategy Permissive, falling back to unsecured: {}",
                    e.to_string().trim_start_matches(ENFORCE_PREFIX)
                ),
            }),
            Err(e) => Err(e),
        }
    }

    fn find_enclave(&self) -> Result<PathBuf, SecurityError> {
        if !cfg!(feature = "security") {
            return Err(SecurityError::NotBuilt);
        }
        let keystore = self.keystore.as_ref().ok_or(SecurityError::NoKeystore)?;
        let enclave = self.enclave_override.as_ref().unwrap_or(&self.enclave);
        let dir = enclave_dir(keystore, enclave)?;
        if !dir.is_dir() {
            return Err(SecurityError::NoEnclave {
                enclave: enclave.clone(),
                keystore: keystore.clone(),
                dir,
            });
        }
        let missing: Vec<String> = ENCLAVE_FILES
            .iter()
            .filter(|f| !dir.join(f).is_file())
            .map(|f| (*f).to_string())
            .collect();
        if !missing.is_empty() {
            return Err(SecurityError::MissingFiles { dir, missing });
        }
        #[cfg(feature = "security")]
        check_identity(&dir)?;
        Ok(dir)
    }
}

/// The enclave's identity, checked before any DDS traffic: `cert.pem` is valid now (not
/// expired, not before its start) and `key.pem` is its private key. RustDDS would otherwise
/// start with an expired certificate or a key that signs nothing its peers can verify.
///
/// # Errors
/// [`SecurityError::BadIdentity`] naming the file and the reason.
#[cfg(feature = "security")]
pub fn check_identity(dir: &Path) -> Result<(), SecurityError> {
    use openssl::asn1::Asn1Time;
    use std::cmp::Ordering;
    let bad = |file: &str, reason: String| SecurityError::BadIdentity {
        file: dir.join(file),
        reason,
    };
    let read = |file: &str| std::fs::read(dir.join(file)).map_err(|e| bad(file, e.to_string()));
    let cert = openssl::x509::X509::from_pem(&read("cert.pem")?)
        .map_err(|e| bad("cert.pem", format!("not a PEM certificate ({e})")))?;
    let now = Asn1Time::days_from_now(0).map_err(|e| bad("cert.pem", e.to_string()))?;
    let cmp = |t: &openssl::asn1::Asn1TimeRef| t.compare(&now).unwrap_or(Ordering::Equal);
    if cmp(cert.not_before()) == Ordering::Greater {
        return Err(bad(
            "cert.pem",
            format!(
                "the identity certificate is not valid before {}",
                cert.not_before()
            ),
        ));
    }
    if cmp(cert.not_after()) == Ordering::Less {
        return Err(bad(
            "cert.pem",
            format!("the identity certificate expired on {}", cert.not_after()),
        ));
    }
    let key = openssl::pkey::PKey::private_key_from_pem(&read("key.pem")?)
        .map_err(|e| bad("key.pem", format!("not a PEM private key ({e})")))?;
    let public = cert
        .public_key()
        .map_err(|e| bad("cert.pem", e.to_string()))?;
    if !public.public_eq(&key) {
        return Err(bad(
            "key.pem",
            "the private key does not match the identity certificate cert.pem".into(),
        ));
    }
    Ok(())
}

/// `<keystore>/enclaves/<enclave without its leading />` (rcl's lookup); the enclave must
/// be a valid enclave path, so it cannot leave the keystore.
///
/// # Errors
/// [`SecurityError::BadEnclave`] for anything but `/` or `/name(/name)*` with names of
/// ASCII letters, digits and `_`.
pub fn enclave_dir(keystore: &Path, enclave: &str) -> Result<PathBuf, SecurityError> {
    let bad = || SecurityError::BadEnclave(enclave.chars().take(MAX_ENCLAVE_CHARS).collect());
    let rest = enclave.strip_prefix('/').ok_or_else(bad)?;
    let mut dir = keystore.join("enclaves");
    if rest.is_empty() {
        return Ok(dir);
    }
    if enclave.len() > MAX_ENCLAVE_CHARS {
        return Err(bad());
    }
    for part in rest.split('/') {
        let ok = !part.is_empty()
            && !part.starts_with(|c: char| c.is_ascii_digit())
            && part.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
        if !ok {
            return Err(bad());
        }
        dir.push(part);
    }
    Ok(dir)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    fn opts(vars: &[(&str, &str)], enclave: Option<&str>) -> SecurityOptions {
        let m: HashMap<String, String> = vars
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        SecurityOptions::from_env(|k| m.get(k).cloned(), enclave.map(String::from))
    }

    /// A keystore with one complete enclave `/ok` and one incomplete `/half`.
    #[cfg(feature = "security")]
    fn keystore(name: &str) -> PathBuf {
        let ks = std::env::temp_dir().join(format!("bevt_sec_{}_{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&ks);
        for (enclave, files) in [("ok", &ENCLAVE_FILES[..]), ("half", &ENCLAVE_FILES[..2])] {
            let d = ks.join("enclaves").join(enclave);
            std::fs::create_dir_all(&d).unwrap();
            for f in files {
                std::fs::write(d.join(f), "x").unwrap();
            }
            if enclave == "ok" {
                let (cert, key) = identity(-1, 30);
                std::fs::write(d.join("cert.pem"), cert).unwrap();
                std::fs::write(d.join("key.pem"), key).unwrap();
            }
        }
        ks
    }

    /// A self-signed P-256 identity valid from `from_days` to `to_days` (relative to now):
    /// (cert.pem, key.pem).
    #[cfg(feature = "security")]
    fn identity(from_days: i64, to_days: i64) -> (Vec<u8>, Vec<u8>) {
        use openssl::{asn1::Asn1Time, ec, nid::Nid, pkey::PKey, x509};
        let group = ec::EcGroup::from_curve_name(Nid::X9_62_PRIME256V1).unwrap();
        let key = PKey::from_ec_key(ec::EcKey::generate(&group).unwrap()).unwrap();
        let mut name = x509::X509NameBuilder::new().unwrap();
        name.append_entry_by_text("CN", "/ok").unwrap();
        let name = name.build();
        let at = |days: i64| {
            let now = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .unwrap()
                .as_secs() as i64;
            Asn1Time::from_unix(now + days * 86_400).unwrap()
        };
        let mut b = x509::X509Builder::new().unwrap();
        b.set_version(2).unwrap();
        b.set_subject_name(&name).unwrap();
        b.set_issuer_name(&name).unwrap();
        b.set_pubkey(&key).unwrap();
        b.set_not_before(&at(from_days)).unwrap();
        b.set_not_after(&at(to_days)).unwrap();
        b.sign(&key, openssl::hash::MessageDigest::sha256())
            .unwrap();
        (
            b.build().to_pem().unwrap(),
            key.private_key_to_pem_pkcs8().unwrap(),
        )
    }

    #[cfg(feature = "security")]
    #[test]
    fn an_expired_future_or_mismatched_identity_is_refused_naming_the_file() {
        let ks = keystore("identity");
        let dir = ks.join("enclaves").join("ok");
        let o = opts(
            &[
                (ENV_ENABLE, "true"),
                (ENV_STRATEGY, "Enforce"),
                (ENV_KEYSTORE, ks.to_str().unwrap()),
            ],
            Some("/ok"),
        );
        assert!(matches!(o.resolve(), Ok(DdsSecurity::Enclave(_))));
        for (from, to, file, why) in [
            (-30, -1, "cert.pem", "expired on"),
            (2, 30, "cert.pem", "not valid before"),
        ] {
            let (cert, key) = identity(from, to);
            std::fs::write(dir.join("cert.pem"), cert).unwrap();
            std::fs::write(dir.join("key.pem"), key).unwrap();
            let e = o.resolve().unwrap_err().to_string();
            assert!(e.contains(file) && e.contains(why), "{e}");
        }
        // A valid certificate with another identity's key.
        let (cert, _) = identity(-1, 30);
        let (_, other_key) = identity(-1, 30);
        std::fs::write(dir.join("cert.pem"), cert).unwrap();
        std::fs::write(dir.join("key.pem"), other_key).unwrap();
        let e = o.resolve().unwrap_err().to_string();
        assert!(e.contains("key.pem") && e.contains("does not match"), "{e}");
        let _ = std::fs::remove_dir_all(&ks);
    }

    #[test]
    fn security_is_on_only_when_ros_security_enable_is_exactly_true() {
        for v in ["TRUE", "1", "yes", "True", ""] {
            let o = opts(&[(ENV_ENABLE, v), (ENV_STRATEGY, "Enforce")], None);
            assert!(!o.enable, "{v:?}");
            assert!(matches!(o.resolve(), Ok(DdsSecurity::Off { .. })), "{v:?}");
        }
        assert!(opts(&[(ENV_ENABLE, "true")], None).enable);
    }

    #[test]
    fn strategy_is_enforce_only_when_exactly_enforce() {
        assert_eq!(
            opts(&[(ENV_STRATEGY, "Enforce")], None).strategy,
            Strategy::Enforce
        );
        for v in ["enforce", "ENFORCE", "Permissive", ""] {
            assert_eq!(
                opts(&[(ENV_STRATEGY, v)], None).strategy,
                Strategy::Permissive
            );
        }
    }

    #[test]
    fn enforce_without_a_keystore_is_an_error_and_permissive_falls_back_with_the_reason() {
        let o = opts(
            &[(ENV_ENABLE, "true"), (ENV_STRATEGY, "Enforce")],
            Some("/ok"),
        );
        let want = if cfg!(feature = "security") {
            SecurityError::NoKeystore
        } else {
            SecurityError::NotBuilt
        };
        assert_eq!(o.resolve(), Err(want));
        let o = opts(&[(ENV_ENABLE, "true"), (ENV_KEYSTORE, "")], Some("/ok"));
        match o.resolve() {
            Ok(DdsSecurity::Off { why }) => assert!(why.contains("falling back"), "{why}"),
            other => panic!("{other:?}"),
        }
    }

    #[cfg(feature = "security")]
    #[test]
    fn enclave_directory_is_looked_up_in_the_keystore_and_checked_for_its_files() {
        let ks = keystore("lookup");
        let k = ks.to_str().unwrap();
        let on = [
            (ENV_ENABLE, "true"),
            (ENV_STRATEGY, "Enforce"),
            (ENV_KEYSTORE, k),
        ];
        assert_eq!(
            opts(&on, Some("/ok")).resolve(),
            Ok(DdsSecurity::Enclave(ks.join("enclaves/ok")))
        );
        // The default enclave `/` is the enclaves directory itself: no identity there.
        assert!(matches!(
            opts(&on, None).resolve(),
            Err(SecurityError::MissingFiles { .. })
        ));
        match opts(&on, Some("/half")).resolve() {
            Err(SecurityError::MissingFiles { missing, .. }) => {
                assert_eq!(missing, ENCLAVE_FILES[2..].to_vec())
            }
            other => panic!("{other:?}"),
        }
        assert!(matches!(
            opts(&on, Some("/absent")).resolve(),
            Err(SecurityError::NoEnclave { .. })
        ));
        // The override wins over --enclave.
        let mut with_override = on.to_vec();
        with_override.push((ENV_ENCLAVE_OVERRIDE, "/ok"));
        assert_eq!(
            opts(&with_override, Some("/absent")).resolve(),
            Ok(DdsSecurity::Enclave(ks.join("enclaves/ok")))
        );
        // Permissive: the same failures start unsecured.
        let permissive = [(ENV_ENABLE, "true"), (ENV_KEYSTORE, k)];
        assert!(matches!(
            opts(&permissive, Some("/half")).resolve(),
            Ok(DdsSecurity::Off { .. })
        ));
        let _ = std::fs::remove_dir_all(&ks);
    }

    #[test]
    fn enclave_paths_cannot_leave_the_keystore() {
        let ks = Path::new("/ks");
        assert_eq!(enclave_dir(ks, "/").unwrap(), ks.join("enclaves"));
        assert_eq!(
            enclave_dir(ks, "/a/b_2").unwrap(),
            ks.join("enclaves/a/b_2")
        );
        for bad in [
            "", "a", "/..", "/a/../b", "/a//b", "/a/", "/a b", "/1a", "//",
        ] {
            assert!(enclave_dir(ks, bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn the_unsecured_warning_says_what_is_exposed() {
        let w = DdsSecurity::default().warning(7).unwrap();
        assert!(w.contains("unauthenticated") && w.contains("domain 7") && w.contains("reinit"));
        assert!(w.contains("parameter services"), "{w}");
        assert_eq!(DdsSecurity::Enclave("/x".into()).warning(7), None);
    }
}
