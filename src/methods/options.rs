//! A method's options, declared once beside its settings: the keys of its scene table
//! (`[simulation.<method>]`, its `Settings` as serde reads them) and its command-line flags
//! ([`MethodType::FLAGS`], each a [`Flag`]). The command line offers the union of every
//! method's flags ([`MethodFlags`]); a flag that several methods declare is one flag, which sets
//! the run method's setting. Whatever the input path (a flag, or one of the five `[simulation]`
//! keys that predate the tables, listed in `crate::scene`), an option the run's method lacks is
//! refused in the same words ([`NoSuchOption`]).
//!
//! [`MethodType::FLAGS`]: super::MethodType::FLAGS
//! [`NoSuchOption`]: super::NoSuchOption

use clap::builder::EnumValueParser;
use clap::parser::ValueSource;
use clap::{Arg, ArgAction, ArgMatches, Args, Command, FromArgMatches};
use serde::Serialize;
use std::str::FromStr;

/// A command-line flag of a method: `--<name>`, its help, how its value is read, and what it
/// sets in the method's settings `S`.
pub struct Flag<S> {
    /// The flag without its dashes, e.g. `band-r`.
    pub name: &'static str,
    pub help: &'static str,
    pub value: FlagValue,
    /// Writes the value (as [`FlagValue`] read it) into the settings.
    pub set: fn(&mut S, toml::Value) -> Result<(), toml::de::Error>,
}

/// How a flag's value is parsed on the command line, and given on as a TOML value.
#[derive(Clone, Copy)]
pub struct FlagValue {
    arg: fn(Arg) -> Arg,
    read: fn(&ArgMatches, &str) -> Option<toml::Value>,
}

impl FlagValue {
    /// One of the names of a `clap::ValueEnum` type (the names serde gives it too).
    pub const fn choice<T>() -> Self
    where
        T: clap::ValueEnum + Serialize + Clone + Send + Sync + 'static,
    {
        Self {
            arg: |a| a.value_parser(EnumValueParser::<T>::new()),
            read: read_as::<T>,
        }
    }

    /// A number (any type that parses from its text, e.g. `u32` or `f64`), called `N` in the
    /// help. A number that the type holds but a TOML value does not (a `u64` past `i64::MAX`:
    /// every flag's value passes through TOML, as a scene file's key would) is refused while
    /// the command line is parsed, naming the flag.
    pub const fn number<T>() -> Self
    where
        T: FromStr + Serialize + Clone + Send + Sync + 'static,
        T::Err: std::fmt::Display,
    {
        Self {
            arg: |a| a.value_parser(parse::<T>).value_name("N"),
            read: read_as::<T>,
        }
    }

    /// A switch without a value: given, it sets `true`.
    pub const SWITCH: Self = Self {
        arg: |a| a.action(ArgAction::SetTrue),
        read: |m, id| m.get_flag(id).then_some(toml::Value::Boolean(true)),
    };
}

fn parse<T: FromStr + Serialize>(text: &str) -> Result<T, String>
where
    T::Err: std::fmt::Display,
{
    let n = text.parse::<T>().map_err(|e| e.to_string())?;
    match toml::Value::try_from(&n) {
        Ok(_) => Ok(n),
        Err(_) => Err(format!(
            "{text} is too large: a setting holds integers up to {}",
            i64::MAX
        )),
    }
}

fn read_as<T: Serialize + Clone + Send + Sync + 'static>(
    m: &ArgMatches,
    id: &str,
) -> Option<toml::Value> {
    let v = m.get_one::<T>(id)?;
    Some(toml::Value::try_from(v).expect("a flag's value is a TOML value"))
}

/// A flag as the command line offers it: every method that declares it, in registry order.
#[derive(Clone)]
pub struct OfferedFlag {
    pub name: &'static str,
    /// `(method, help)` of each method that declares it.
    pub declared_by: Vec<(&'static str, &'static str)>,
    value: FlagValue,
}

impl OfferedFlag {
    pub fn new(name: &'static str, value: FlagValue) -> Self {
        Self {
            name,
            declared_by: vec![],
            value,
        }
    }

    /// Its argument id, apart from the commands' own arguments.
    fn id(&self) -> String {
        format!("method-flag-{}", self.name)
    }

    fn arg(&self) -> Arg {
        let methods: Vec<&str> = self.declared_by.iter().map(|d| d.0).collect();
        let heading = match methods.len() {
            1 => format!("Method {}", methods[0]),
            _ => format!("Methods {}", methods.join(", ")),
        };
        let help = match self.declared_by.as_slice() {
            [(_, help)] => help.to_string(),
            all => all
                .iter()
                .map(|(m, help)| format!("{m}: {help}"))
                .collect::<Vec<_>>()
                .join(" "),
        };
        let arg = Arg::new(self.id())
            .long(self.name)
            .value_name(self.name.to_uppercase().replace('-', "_"))
            .help(help)
            .help_heading(heading);
        (self.value.arg)(arg)
    }
}

/// The method flags given on a command line, each `(name, value)`: clap's arguments for the
/// union of the methods' flags ([`super::MethodKind::flags`]). A command that has an argument
/// of the same long name itself keeps its own (`cellflip bench --band` takes a list).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MethodFlags(pub Vec<(&'static str, toml::Value)>);

impl MethodFlags {
    /// These flags and `--<name> <value>`, as the command line would give them.
    pub fn with(mut self, name: &'static str, value: impl Serialize) -> Self {
        let value = toml::Value::try_from(value).expect("a flag's value is a TOML value");
        self.0.push((name, value));
        self
    }
}

impl FromArgMatches for MethodFlags {
    fn from_arg_matches(m: &ArgMatches) -> Result<Self, clap::Error> {
        let given = super::MethodKind::flags().into_iter().filter_map(|f| {
            let id = f.id();
            let ours = m.try_contains_id(&id).unwrap_or(false);
            let typed = ours && m.value_source(&id) == Some(ValueSource::CommandLine);
            typed.then(|| (f.value.read)(m, &id).map(|v| (f.name, v)))?
        });
        Ok(Self(given.collect()))
    }

    fn update_from_arg_matches(&mut self, m: &ArgMatches) -> Result<(), clap::Error> {
        *self = Self::from_arg_matches(m)?;
        Ok(())
    }
}

impl Args for MethodFlags {
    fn augment_args(cmd: Command) -> Command {
        super::MethodKind::flags().iter().fold(cmd, |cmd, f| {
            let taken = cmd.get_arguments().any(|a| a.get_long() == Some(f.name));
            match taken {
                true => cmd,
                false => cmd.arg(f.arg()),
            }
        })
    }

    fn augment_args_for_update(cmd: Command) -> Command {
        Self::augment_args(cmd)
    }
}
