//! Options whose value is one of a few names (`--fit scale`, `fit = "scale"` in a config file,
//! `fit="scale"` in Python): each such enum states its names and their help once, with
//! [`choice!`](crate::choice!), and every front end reads them from there. The library does not
//! depend on the command-line parser; the binary makes its value parsers from [`Choice::ALL`].

/// An option's value among a few names.
pub trait Choice: Sized + Copy + PartialEq + 'static {
    /// Every value with its name and a line of help, in the order help lists them.
    const ALL: &'static [(Self, &'static str, &'static str)];

    /// The value's name.
    fn name(self) -> &'static str {
        Self::ALL.iter().find(|c| c.0 == self).map_or("", |c| c.1)
    }

    /// The value of a name, in any case.
    fn from_name(s: &str) -> Option<Self> {
        let s = s.trim();
        Self::ALL
            .iter()
            .find(|c| c.1.eq_ignore_ascii_case(s))
            .map(|c| c.0)
    }

    /// The names, for messages: "a, b, c".
    fn names() -> String {
        Self::ALL.iter().map(|c| c.1).collect::<Vec<_>>().join(", ")
    }

    /// [`Choice::from_name`], or a message that lists the names.
    fn parse_name(s: &str) -> Result<Self, String> {
        Self::from_name(s).ok_or_else(|| format!("{s:?} is not one of {}", Self::names()))
    }
}

/// An enum whose values are named options: `Variant = "name", "help"` each (the help is also
/// the variant's first line of documentation). Implements [`Choice`], `Display`, `FromStr` and
/// serde by name.
#[macro_export]
macro_rules! choice {
    (
        $(#[$meta:meta])*
        $vis:vis enum $name:ident {
            $( $(#[$vmeta:meta])* $variant:ident = $text:literal, $help:literal ),+ $(,)?
        }
    ) => {
        $(#[$meta])*
        $vis enum $name {
            $( #[doc = $help] $(#[$vmeta])* $variant, )+
        }

        impl $crate::choice::Choice for $name {
            const ALL: &'static [(Self, &'static str, &'static str)] =
                &[$(($name::$variant, $text, $help)),+];
        }

        impl std::fmt::Display for $name {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str($crate::choice::Choice::name(*self))
            }
        }

        impl std::str::FromStr for $name {
            type Err = String;
            fn from_str(s: &str) -> Result<Self, String> {
                <$name as $crate::choice::Choice>::parse_name(s)
            }
        }

        impl serde::Serialize for $name {
            fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                s.serialize_str($crate::choice::Choice::name(*self))
            }
        }

        impl<'de> serde::Deserialize<'de> for $name {
            fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
                let s = <String as serde::Deserialize>::deserialize(d)?;
                <$name as $crate::choice::Choice>::parse_name(&s).map_err(serde::de::Error::custom)
            }
        }
    };
}

#[cfg(test)]
mod tests {

    crate::choice! {
        #[derive(Clone, Copy, Debug, PartialEq, Eq)]
        enum Colour {
            Red = "red", "A warm one.",
            DeepBlue = "deep-blue", "A cold one.",
        }
    }

    #[test]
    fn names_read_back_in_any_case_and_others_are_told_the_names() {
        assert_eq!(Colour::DeepBlue.to_string(), "deep-blue");
        assert_eq!("Deep-Blue".parse::<Colour>(), Ok(Colour::DeepBlue));
        assert_eq!(
            "green".parse::<Colour>(),
            Err("\"green\" is not one of red, deep-blue".to_string())
        );
        let json = serde_json::to_string(&Colour::Red).unwrap();
        assert_eq!(json, "\"red\"");
        assert_eq!(serde_json::from_str::<Colour>(&json).unwrap(), Colour::Red);
        assert!(serde_json::from_str::<Colour>("\"violet\"").is_err());
    }
}
