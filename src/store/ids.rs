//! Run and dataset ids: `{prefix}-{yyyymmdd}t{hhmmss}-{6 base32 chars}`, e.g.
//! `exp-20261122t101500-k3v9qa`. Lower case only, so an id is also a safe folder name and a URL
//! segment; the UTC time stamp makes ids of one kind sort by creation time.

use super::error::StoreError;
use rand::Rng;
use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;
use std::time::SystemTime;

pub const MAX_ID_LEN: usize = 64;

/// Crockford's base32 alphabet in lower case: no i, l, o, u to misread.
const BASE32: &[u8; 32] = b"0123456789abcdefghjkmnpqrstvwxyz";

fn check(s: &str) -> Result<(), StoreError> {
    let ok = !s.is_empty()
        && s.len() <= MAX_ID_LEN
        && !s.starts_with('-')
        && s.bytes()
            .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'-');
    if ok {
        Ok(())
    } else {
        Err(StoreError::BadId(s.chars().take(MAX_ID_LEN).collect()))
    }
}

/// `yyyymmddthhmmss` in UTC.
fn stamp(now: SystemTime) -> String {
    humantime::format_rfc3339_seconds(now)
        .to_string()
        .chars()
        .filter_map(|c| match c {
            '0'..='9' => Some(c),
            'T' => Some('t'),
            _ => None,
        })
        .collect()
}

pub(crate) fn random_suffix(len: usize) -> String {
    let mut rng = rand::thread_rng();
    (0..len)
        .map(|_| BASE32[rng.gen_range(0..BASE32.len())] as char)
        .collect()
}

pub(crate) fn generate(prefix: &str) -> String {
    format!("{prefix}-{}-{}", stamp(SystemTime::now()), random_suffix(6))
}

macro_rules! id_type {
    ($(#[$doc:meta])* $name:ident) => {
        $(#[$doc])*
        #[derive(Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
        #[serde(try_from = "String", into = "String")]
        pub struct $name(String);

        impl $name {
            pub fn as_str(&self) -> &str {
                &self.0
            }
        }

        impl FromStr for $name {
            type Err = StoreError;
            fn from_str(s: &str) -> Result<Self, StoreError> {
                check(s)?;
                Ok(Self(s.to_string()))
            }
        }

        impl TryFrom<String> for $name {
            type Error = StoreError;
            fn try_from(s: String) -> Result<Self, StoreError> {
                check(&s)?;
                Ok(Self(s))
            }
        }

        impl From<$name> for String {
            fn from(id: $name) -> String {
                id.0
            }
        }

        impl AsRef<str> for $name {
            fn as_ref(&self) -> &str {
                &self.0
            }
        }

        impl fmt::Display for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(&self.0)
            }
        }
    };
}

id_type!(
    /// The id of a run: its folder name under `runs/`.
    RunId
);
id_type!(
    /// The id of a stored dataset: its folder name under `datasets/`.
    DatasetId
);

impl RunId {
    /// A fresh id for a run of `kind` (prefix `exp`, `ana`, `cmp`, `dia` or `swp`).
    pub fn generate(kind: super::record::RunKind) -> Self {
        Self(generate(kind.id_prefix()))
    }
}

impl DatasetId {
    /// A fresh dataset id (prefix `ds`).
    pub fn generate() -> Self {
        Self(generate("ds"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::RunKind;

    #[test]
    fn generated_ids_are_valid_and_sort_by_time() {
        let id = RunId::generate(RunKind::Experiment);
        assert!(id.as_str().starts_with("exp-"), "{id}");
        assert_eq!(
            id.as_str().len(),
            "exp-20261122t101500-abcdef".len(),
            "{id}"
        );
        assert_eq!(id.as_str().parse::<RunId>().unwrap(), id);
        assert!(DatasetId::generate().as_str().starts_with("ds-"));
        assert!(RunId::generate(RunKind::Diagnosis)
            .as_str()
            .starts_with("dia-"));
        let t0 = SystemTime::UNIX_EPOCH + std::time::Duration::from_secs(1_800_000_000);
        let t1 = t0 + std::time::Duration::from_secs(1);
        assert_eq!(stamp(t0), "20270115t080000");
        assert!(stamp(t0) < stamp(t1));
    }

    #[test]
    fn malformed_ids_are_refused() {
        for bad in [
            "",
            "-abc",
            "ABC",
            "a_b",
            "a/b",
            "..",
            "a.b",
            "é",
            "a b",
            &"a".repeat(65),
        ] {
            assert!(bad.parse::<RunId>().is_err(), "{bad:?}");
            assert!(serde_json::from_value::<DatasetId>(serde_json::json!(bad)).is_err());
        }
        assert!("a".repeat(64).parse::<RunId>().is_ok());
        assert!("0-a-".parse::<RunId>().is_ok());
    }
}
