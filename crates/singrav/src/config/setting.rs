//! Settings by their dotted path in the configuration's JSON (`losses.rgb`,
//! `schedule.scales`): `--set` and the list of settings two runs differ in.

use std::collections::BTreeMap;

use serde_json::Value;

use super::TrainConfig;
use crate::error::{invalid, Result};

impl TrainConfig {
    /// Sets one setting by its dotted path to a JSON value, as `volgen train --set PATH=VALUE`
    /// does: for the settings without a flag of their own (a loss weight, the channels, the
    /// schedule). `value` is read as JSON (`50`, `true`, `[240, 160]`), and as a string where
    /// it is not JSON; a whole group can be set at once (`--set 'noise={...}'`). Call
    /// [`TrainConfig::validate`] after the last change.
    ///
    /// ```
    /// use singrav::TrainConfig;
    /// let config = TrainConfig::preset("tiny")?.with_setting("losses.rgb", "50")?;
    /// assert_eq!(config.losses.rgb, 50.0);
    /// let err = TrainConfig::preset("tiny")?.with_setting("losses.rbg", "1").unwrap_err();
    /// assert!(err.to_string().contains("losses.rgb"), "the known settings are listed: {err}");
    /// # Ok::<(), singrav::Error>(())
    /// ```
    ///
    /// # Errors
    /// [`crate::Error::Invalid`] naming the path when it does not exist or the value is not of
    /// its type.
    pub fn with_setting(self, path: &str, value: &str) -> Result<Self> {
        let mut json = serde_json::to_value(&self)
            .map_err(|e| invalid(path, format!("cannot list the settings: {e}")))?;
        let Some(slot) = path
            .split('.')
            .try_fold(&mut json, |node, key| node.as_object_mut()?.get_mut(key))
        else {
            let known: Vec<String> = leaves(&serde_json::to_value(&self).unwrap_or_default())
                .into_keys()
                .collect();
            return Err(invalid(
                path,
                format!("no such setting; the settings are {}", known.join(", ")),
            ));
        };
        let parsed =
            serde_json::from_str(value).unwrap_or_else(|_| Value::String(value.to_string()));
        let was = std::mem::replace(slot, parsed);
        serde_json::from_value(json).map_err(|e| {
            invalid(
                path,
                format!("`{value}` is not a value of this setting (it was {was}): {e}"),
            )
        })
    }
}

/// The settings (dotted paths) in which `a` and `b` differ, each with its two values:
/// `["losses.rgb (50.0 against 10.0)", ...]`, in path order.
///
/// ```
/// use singrav::config::settings_that_differ;
/// let tiny = singrav::TrainConfig::preset("tiny")?;
/// let other = tiny.clone().with_setting("losses.rgb", "1")?;
/// assert_eq!(settings_that_differ(&tiny, &other), ["losses.rgb (50.0 against 1.0)"]);
/// # Ok::<(), singrav::Error>(())
/// ```
pub fn settings_that_differ(a: &TrainConfig, b: &TrainConfig) -> Vec<String> {
    let flat = |c: &TrainConfig| leaves(&serde_json::to_value(c).unwrap_or_default());
    let (a, b) = (flat(a), flat(b));
    let paths: std::collections::BTreeSet<&String> = a.keys().chain(b.keys()).collect();
    paths
        .into_iter()
        .filter(|path| a.get(*path) != b.get(*path))
        .map(|path| {
            let show = |leaves: &BTreeMap<String, Value>| {
                leaves.get(path).cloned().unwrap_or_default().to_string()
            };
            format!("{path} ({} against {})", show(&a), show(&b))
        })
        .collect()
}

/// Every setting of a configuration's JSON by its dotted path: objects are groups, anything
/// else (numbers, lists, `null`) a setting.
fn leaves(json: &Value) -> BTreeMap<String, Value> {
    fn walk(prefix: &str, node: &Value, out: &mut BTreeMap<String, Value>) {
        match node {
            Value::Object(fields) if !prefix.is_empty() || !fields.is_empty() => {
                for (key, child) in fields {
                    let path = if prefix.is_empty() {
                        key.clone()
                    } else {
                        format!("{prefix}.{key}")
                    };
                    walk(&path, child, out);
                }
            }
            _ => {
                out.insert(prefix.to_string(), node.clone());
            }
        }
    }
    let mut out = BTreeMap::new();
    walk("", json, &mut out);
    out
}

#[cfg(test)]
mod tests {
    use super::{leaves, settings_that_differ};
    use crate::config::{ScaleViews, TrainConfig};

    #[test]
    fn settings_are_listed_by_their_dotted_paths() {
        let json = serde_json::to_value(TrainConfig::preset("tiny").unwrap()).unwrap();
        let paths: Vec<String> = leaves(&json).into_keys().collect();
        for path in [
            "version",
            "losses.rgb",
            "pyramid.volume_sizes",
            "schedule.scale_views",
            "run.bounds",
            "active_set.from_scale",
        ] {
            assert!(paths.iter().any(|p| p == path), "{path}: {paths:?}");
        }
        assert!(!paths.iter().any(|p| p == "losses"));
    }

    #[test]
    fn per_scale_views_and_bounds_are_settable_on_presets_without_them() {
        // `micro` has neither, so the fields must be listed (as null) for `--set` to find them.
        let micro = TrainConfig::preset("micro").unwrap();
        assert_eq!(
            (micro.schedule.scale_views.clone(), micro.run.bounds),
            (None, None)
        );
        let views = r#"[{"generated": 2, "reconstruction": 8}, {"generated": 2, "reconstruction": 8},
            {"generated": 1, "reconstruction": 2}]"#;
        let set = micro
            .clone()
            .with_setting("schedule.scale_views", views)
            .unwrap()
            .with_setting("run.bounds", r#"{"min": [-2, -2, 0], "max": [2, 2, 1]}"#)
            .unwrap();
        set.validate().unwrap();
        assert_eq!(
            set.views(1),
            ScaleViews {
                generated: 2,
                reconstruction: 8
            }
        );
        assert_eq!(
            set.views(3),
            ScaleViews {
                generated: 1,
                reconstruction: 2
            }
        );
        assert_eq!(set.run.bounds.unwrap().max, [2.0, 2.0, 1.0]);
    }

    #[test]
    fn bad_paths_and_values_are_refused_naming_the_path() {
        let micro = TrainConfig::preset("micro").unwrap();
        for (path, value) in [
            ("lambda_color", "50"),
            ("losses", "3"),
            ("losses.rgb.x", "1"),
            ("pyramid.layers", "many"),
            ("losses.rgb", "[1]"),
        ] {
            let err = micro
                .clone()
                .with_setting(path, value)
                .unwrap_err()
                .to_string();
            assert!(err.contains(path), "{path}={value}: {err}");
        }
        // A whole group at once, when complete.
        let mut noise = serde_json::to_value(&micro.noise).unwrap();
        noise["first_amplitude"] = 2.0.into();
        let set = micro
            .clone()
            .with_setting("noise", &noise.to_string())
            .unwrap();
        assert_eq!(set.noise.first_amplitude, 2.0);
        assert_eq!(
            settings_that_differ(&micro, &set),
            ["noise.first_amplitude (1.0 against 2.0)"]
        );
    }
}
