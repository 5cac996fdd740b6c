//! `Display` and `FromStr` of a closed vocabulary from its `as_str` and `ALL`: the wire word is
//! written once, in `as_str`'s exhaustive match, and parsing is its inverse.

/// `text_enum!(Type, "noun")`: `Display` writes `as_str()`, `FromStr` finds the member of
/// `Type::ALL` whose `as_str()` is the text, else "unknown noun 'text'".
macro_rules! text_enum {
    ($t:ty, $noun:expr) => {
        impl ::std::fmt::Display for $t {
            fn fmt(&self, f: &mut ::std::fmt::Formatter<'_>) -> ::std::fmt::Result {
                f.write_str(self.as_str())
            }
        }

        impl ::std::str::FromStr for $t {
            type Err = String;
            fn from_str(s: &str) -> Result<Self, String> {
                Self::ALL
                    .into_iter()
                    .find(|v| v.as_str() == s)
                    .ok_or_else(|| format!("unknown {} '{s}'", $noun))
            }
        }
    };
}

pub(crate) use text_enum;
