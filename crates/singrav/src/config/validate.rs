//! [`TrainConfig::validate`]: the sizes agree and every setting is in range, each refusal
//! naming the setting by its dotted path (as `--set` takes it).

use rgbd_dataset::SceneBounds;

use super::{SwdFeatures, TrainConfig};
use crate::error::{invalid, Result};

/// Errors, naming `field`, unless the loss weight `value` is finite and >= 0.
fn check_weight(field: &str, value: f64) -> Result<()> {
    check_non_negative(field, "weight", value)
}

/// Errors unless `value` (a `what`) is finite and not negative.
fn check_non_negative(field: &str, what: &str, value: f64) -> Result<()> {
    if value >= 0.0 && value.is_finite() {
        Ok(())
    } else {
        Err(invalid(
            field,
            format!("expected a finite {what} >= 0, got {value}"),
        ))
    }
}

impl TrainConfig {
    /// Checks that the sizes agree and every setting is in range.
    ///
    /// ```
    /// let mut config = singrav::TrainConfig::preset("micro")?;
    /// config.validate()?;
    /// config.losses.rgb = -1.0;
    /// let err = config.validate().unwrap_err().to_string();
    /// assert!(err.contains("losses.rgb"), "{err}");
    /// # Ok::<(), singrav::Error>(())
    /// ```
    pub fn validate(&self) -> Result<()> {
        self.validate_pyramid()?;
        self.validate_schedule()?;
        self.validate_losses()?;
        self.validate_active_set()?;
        self.validate_rendering_and_noise()?;
        self.validate_run()
    }

    fn validate_pyramid(&self) -> Result<()> {
        let pyramid = &self.pyramid;
        let n = pyramid.volume_sizes.len();
        if n == 0 {
            return Err(invalid(
                "pyramid.volume_sizes",
                "need at least one 3D scale",
            ));
        }
        if pyramid.image_sizes.len() != n || pyramid.samples.len() != n {
            return Err(invalid(
                "pyramid",
                format!(
                    "volume_sizes, image_sizes and samples need one entry per 3D scale; have {}, {} and {}",
                    n,
                    pyramid.image_sizes.len(),
                    pyramid.samples.len()
                ),
            ));
        }
        let field = 2 * pyramid.layers + 1;
        if let Some(size) = pyramid.image_sizes.iter().find(|&&s| s <= field) {
            return Err(invalid(
                "pyramid.image_sizes",
                format!("{size} is not larger than the critics' receptive field {field}"),
            ));
        }
        if pyramid.volume_sizes.contains(&0) || pyramid.samples.contains(&0) {
            return Err(invalid(
                "pyramid.volume_sizes / pyramid.samples",
                "must be positive",
            ));
        }
        if pyramid.fit_size.is_some_and(|size| size < 2) {
            return Err(invalid(
                "pyramid.fit_size",
                "a fitted volume needs an edge of at least 2 voxels",
            ));
        }
        if pyramid.layers < 2 || pyramid.channels == 0 || pyramid.upsampler_widths.contains(&0) {
            return Err(invalid(
                "pyramid.layers / pyramid.channels",
                "need at least 2 layers and positive widths",
            ));
        }
        Ok(())
    }

    fn validate_schedule(&self) -> Result<()> {
        let schedule = &self.schedule;
        let scales = self.scales();
        if schedule.scales.len() != scales {
            return Err(invalid(
                "schedule.scales",
                format!(
                    "needs one entry per scale ({scales}), has {}",
                    schedule.scales.len()
                ),
            ));
        }
        if schedule.d_steps == 0 || schedule.g_steps == 0 {
            return Err(invalid(
                "schedule.d_steps / schedule.g_steps",
                "must be positive",
            ));
        }
        if schedule.views_per_step == 0 {
            return Err(invalid("schedule.views_per_step", "must be positive"));
        }
        if let Some(views) = &schedule.scale_views {
            if views.len() != scales
                || views
                    .iter()
                    .any(|v| v.generated == 0 || v.reconstruction == 0)
            {
                return Err(invalid(
                    "schedule.scale_views",
                    format!(
                        "needs one entry per scale ({scales}) with positive generated and \
                         reconstruction views, has {views:?}"
                    ),
                ));
            }
        }
        for (i, s) in schedule.scales.iter().enumerate() {
            if s.iterations == 0 || s.reconstruction_only > s.iterations {
                return Err(invalid(
                    "schedule.scales",
                    format!(
                        "scale {}: needs at least one iteration and no more reconstruction-only \
                         iterations than iterations, has {} of {}",
                        i + 1,
                        s.reconstruction_only,
                        s.iterations
                    ),
                ));
            }
        }
        if schedule.reconstruction_pixels == Some(0) {
            return Err(invalid(
                "schedule.reconstruction_pixels",
                "must be positive (or null for whole views)",
            ));
        }
        let rate = schedule.learning_rate;
        if !(rate.is_finite() && rate > 0.0) {
            return Err(invalid(
                "schedule.learning_rate",
                format!("expected a finite learning rate > 0, got {rate}"),
            ));
        }
        Ok(())
    }

    fn validate_losses(&self) -> Result<()> {
        let losses = &self.losses;
        let penalty = ("critics.gradient_penalty", self.critics.gradient_penalty);
        for (field, weight) in losses.weights().into_iter().chain([penalty]) {
            check_weight(field, weight)?;
        }
        // The terms on the samples' rendered opacity read it from the critics' views.
        for (field, weight) in [
            ("losses.height_profile", losses.height_profile),
            ("losses.opacity_binary", losses.opacity_binary),
        ] {
            if weight > 0.0 && !self.critics.opacity {
                return Err(invalid(
                    field,
                    format!(
                        "compares the samples' rendered opacity, which the critics' views hold \
                         only with critics.opacity on (--no-opacity turns it off); set \
                         {field}=0 or critics.opacity=true"
                    ),
                ));
            }
        }
        if let Some(grid) = losses.colour_grid {
            // Image sizes are checked before the losses, so the smallest exists.
            let smallest = self.pyramid.image_sizes.iter().copied().min().unwrap_or(0);
            if !(1..=smallest).contains(&grid) {
                return Err(invalid(
                    "losses.colour_grid",
                    format!(
                        "expected cells per side from 1 to the smallest rendering's {smallest} \
                         pixels (every cell needs a pixel), got {grid}"
                    ),
                ));
            }
        }
        let volume_scales = self.scales() - 1;
        if let Some(last) = self.critics.volume_until_scale {
            if !(1..=volume_scales).contains(&last) {
                return Err(invalid(
                    "critics.volume_until_scale",
                    format!("expected one of the 3D scales 1 to {volume_scales}, got {last}"),
                ));
            }
        }
        if !self.ablations.use_swd && losses.swd_features != SwdFeatures::PatchPyramid {
            return Err(invalid(
                "losses.swd_features",
                "VGG-19 features need the SWD loss (ablations.use_swd); without it they would \
                 go unused",
            ));
        }
        Ok(())
    }

    fn validate_active_set(&self) -> Result<()> {
        let Some(from) = self.active_set.from_scale else {
            return Ok(());
        };
        if from < 2 {
            return Err(invalid(
                "active_set.from_scale",
                format!(
                    "expected a 3D scale >= 2 (the coarsest, 1, has no coarser volume to take \
                     the active set from), got {from}"
                ),
            ));
        }
        let threshold = self.active_set.threshold;
        if !(threshold.is_finite() && threshold > 0.0) {
            return Err(invalid(
                "active_set.threshold",
                format!("expected a finite density > 0, got {threshold}"),
            ));
        }
        Ok(())
    }

    fn validate_rendering_and_noise(&self) -> Result<()> {
        let rendering = &self.rendering;
        let density_ok = rendering.density_scale.is_finite()
            && rendering.density_scale > 0.0
            && rendering.density_shift.is_finite();
        if !density_ok
            || rendering
                .background
                .iter()
                .any(|c| !(0.0..=1.0).contains(c))
        {
            return Err(invalid(
                "rendering.density_scale / rendering.density_shift / rendering.background",
                "need a positive density scale, a finite shift and a background in [0, 1]",
            ));
        }
        let noise = &self.noise;
        check_non_negative(
            "noise.amplitude_factor",
            "amplitude factor",
            noise.amplitude_factor,
        )?;
        check_non_negative("noise.first_amplitude", "amplitude", noise.first_amplitude)?;
        check_non_negative(
            "noise.reconstruction_lr",
            "learning rate",
            noise.reconstruction_lr,
        )
    }

    fn validate_run(&self) -> Result<()> {
        if let Some(bounds) = self.run.bounds {
            SceneBounds::new(bounds.min, bounds.max)?;
        }
        if let Some(every) = self.run.holdout.filter(|&every| every < 2) {
            return Err(invalid(
                "run.holdout",
                format!("expected every N-th view held out with N >= 2, got {every}"),
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use crate::config::TrainConfig;

    #[test]
    fn active_set_and_sample_opacity_settings_out_of_range_are_refused_by_name() {
        let micro = TrainConfig::preset("micro").unwrap();
        let refused = |setting: &str, value: &str| {
            let err = micro
                .clone()
                .with_setting(setting, value)
                .and_then(|c| c.validate())
                .unwrap_err()
                .to_string();
            assert!(err.contains(setting), "{setting}={value}: {err}");
        };
        refused("active_set.from_scale", "1");
        refused("active_set.from_scale", "0");
        let sparse = micro
            .clone()
            .with_setting("active_set.from_scale", "2")
            .unwrap();
        sparse.validate().unwrap();
        for bad in ["0", "-0.1"] {
            let err = sparse
                .clone()
                .with_setting("active_set.threshold", bad)
                .unwrap()
                .validate()
                .unwrap_err()
                .to_string();
            assert!(err.contains("active_set.threshold"), "{err}");
        }
        refused("noise.reconstruction_lr", "-0.01");
        for field in ["losses.height_profile", "losses.opacity_binary"] {
            refused(field, "-1");
            let mut blind = micro.clone().with_setting(field, "1").unwrap();
            blind.critics.opacity = false;
            let message = blind.validate().unwrap_err().to_string();
            assert!(
                message.contains("critics.opacity") && message.contains(field),
                "{message}"
            );
        }
    }

    #[test]
    fn every_loss_weight_rate_and_amplitude_out_of_range_is_refused_by_its_path() {
        let micro = TrainConfig::preset("micro").unwrap();
        for (field, bad) in [
            ("losses.rgb", "-1"),
            ("losses.depth", "-1"),
            ("losses.swd", "-1"),
            ("losses.colour_distribution", "-1"),
            ("losses.fitted", "-1"),
            ("critics.gradient_penalty", "-0.5"),
            ("schedule.learning_rate", "0"),
            ("noise.first_amplitude", "-1"),
            ("run.holdout", "1"),
            ("critics.volume_until_scale", "0"),
            ("critics.volume_until_scale", "3"),
            ("losses.colour_grid", "0"),
            ("losses.colour_grid", "100"),
        ] {
            let err = micro
                .clone()
                .with_setting(field, bad)
                .and_then(|c| c.validate())
                .unwrap_err()
                .to_string();
            assert!(err.contains(field), "{field}={bad}: {err}");
        }
    }
}
