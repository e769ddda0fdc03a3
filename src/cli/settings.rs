//! A training configuration from a preset, the flags, then `--set PATH=VALUE`: every flag
//! names the settings it changes, so a `--set` of one of them (or of a group holding one) is an
//! error naming both rather than one silently replacing the other.

use anyhow::{bail, Context, Result};
use singrav::TrainConfig;

/// A configuration being built, with the settings the flags gave so far.
pub struct Settings {
    config: TrainConfig,
    /// Each flag given and the dotted paths of the settings it changes.
    flags: Vec<(&'static str, &'static [&'static str])>,
}

impl Settings {
    /// Starts from `config` (a preset).
    pub fn new(config: TrainConfig) -> Self {
        Self {
            config,
            flags: Vec::new(),
        }
    }

    /// Applies `flag`, which changes the settings at `paths` (and no others) as `change` does.
    pub fn flag(
        &mut self,
        flag: &'static str,
        paths: &'static [&'static str],
        change: impl FnOnce(&mut TrainConfig) -> Result<()>,
    ) -> Result<()> {
        change(&mut self.config).with_context(|| flag)?;
        self.flags.push((flag, paths));
        Ok(())
    }

    /// The flag that changed the setting at `path` (or one in the group `path` names), if one
    /// did.
    pub fn flag_of(&self, path: &str) -> Option<&'static str> {
        self.flags
            .iter()
            .find(|(_, paths)| paths.iter().any(|given| overlap(given, path)))
            .map(|(flag, _)| *flag)
    }

    /// The configuration so far (the preset and the flags).
    #[cfg(test)]
    pub fn config(&self) -> &TrainConfig {
        &self.config
    }

    /// Applies each `--set PATH=VALUE` of `settings` after the flags, then validates. Errors
    /// when a flag changed the same setting, naming both.
    pub fn set(mut self, settings: &[String]) -> Result<TrainConfig> {
        for setting in settings {
            let (path, value) = setting.split_once('=').with_context(|| {
                format!("--set {setting}: expected PATH=VALUE, e.g. --set losses.rgb=50")
            })?;
            let path = path.trim();
            if let Some(flag) = self.flag_of(path) {
                bail!(
                    "--set {setting} and {flag} both set {path}: give one of them (a flag's \
                     setting is never replaced)"
                );
            }
            self.config = self
                .config
                .with_setting(path, value.trim())
                .with_context(|| format!("--set {setting}"))?;
        }
        self.config.validate()?;
        Ok(self.config)
    }
}

/// Whether a `--set PATH=VALUE` of `settings` sets the setting at `path` (or a group holding
/// it).
pub fn names_setting(settings: &[String], path: &str) -> bool {
    settings
        .iter()
        .filter_map(|setting| setting.split_once('='))
        .any(|(given, _)| overlap(given.trim(), path))
}

/// Whether two dotted paths name the same setting, or one a group holding the other.
fn overlap(a: &str, b: &str) -> bool {
    let within = |inner: &str, outer: &str| {
        inner
            .strip_prefix(outer)
            .is_some_and(|rest| rest.is_empty() || rest.starts_with('.'))
    };
    within(a, b) || within(b, a)
}

#[cfg(test)]
mod tests {
    use super::{overlap, Settings};
    use singrav::TrainConfig;

    #[test]
    fn a_set_of_what_a_flag_set_is_an_error_naming_both() {
        let mut settings = Settings::new(TrainConfig::preset("micro").unwrap());
        settings
            .flag("--layers", &["pyramid.layers"], |c| {
                c.pyramid.layers = 4;
                Ok(())
            })
            .unwrap();
        for clash in ["pyramid.layers=3", "pyramid={}"] {
            let mut again = Settings::new(TrainConfig::preset("micro").unwrap());
            again.flags = settings.flags.clone();
            let err = again.set(&[clash.into()]).unwrap_err().to_string();
            assert!(err.contains("--layers") && err.contains(clash), "{err}");
        }
        let config = settings.set(&["pyramid.channels=8".into()]).unwrap();
        assert_eq!((config.pyramid.layers, config.pyramid.channels), (4, 8));
        assert!(overlap("run", "run.seed") && overlap("run.seed", "run.seed"));
        assert!(!overlap("run.seed", "run.seeds") && !overlap("losses.rgb", "losses.rgb2"));
    }
}
