//! Losses as data: every term an iteration can report is a row of one table ([`LossTerm`]:
//! its key in the log, its short name on the progress bar, its description in messages and the
//! setting that weighs it); a generator step collects its weighted terms in order
//! ([`StepTerms`]), sums them for the backward pass and reads all their values back in one
//! transfer; an iteration reports each term's mean over its steps ([`StepLosses`]). A new loss
//! term is a row here, its weight in [`crate::config::Losses`] and one `add` where it is
//! computed (docs/architecture.md has the recipe).

use candle_core::{DType, Device, Tensor};
use serde::ser::{Serialize, SerializeMap, Serializer};

use crate::error::Result;

/// Defines [`LossTerm`] from its table: per term its variant, log key, short name, description
/// and weight (a dotted path of the configuration, or `None`), in log order.
macro_rules! loss_terms {
    ($(
        $(#[$doc:meta])*
        $term:ident: $key:literal, $short:literal, $describe:literal, $weight:expr;
    )*) => {
        /// Every loss term an iteration can report, in the order `log.jsonl` writes them.
        #[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
        pub enum LossTerm {
            $($(#[$doc])* $term,)*
        }

        impl LossTerm {
            /// Every term, in log order.
            pub const ALL: [LossTerm; [$($key),*].len()] = [$(LossTerm::$term),*];

            /// The term's key in the loss log (and in `volgen demo`'s summary).
            pub fn key(self) -> &'static str {
                match self {
                    $(LossTerm::$term => $key,)*
                }
            }

            /// The term's name on `volgen train`'s progress bar: its key, or a shorter form of
            /// it.
            pub fn short_name(self) -> &'static str {
                match self {
                    $(LossTerm::$term => $short,)*
                }
            }

            /// The term in words, for messages ("the RGB reconstruction is NaN").
            pub fn describe(self) -> &'static str {
                match self {
                    $(LossTerm::$term => $describe,)*
                }
            }

            /// The dotted path of the setting that weighs the term, if one does.
            pub fn weight(self) -> Option<&'static str> {
                match self {
                    $(LossTerm::$term => $weight,)*
                }
            }
        }
    };
}

loss_terms! {
    /// Critic loss `mean D(fake) - mean D(real)` (before the penalty).
    Critic: "critic", "D", "critic loss", None;
    /// The critic's gradient penalty (weighted).
    Penalty: "penalty", "gp", "gradient penalty", Some("critics.gradient_penalty");
    /// Generator adversarial loss `-mean D(fake)`.
    Adversarial: "adversarial", "adv", "adversarial loss", None;
    /// Weighted reconstruction of the views' RGB, `losses.rgb * mse`.
    Rgb: "rgb", "rgb", "RGB reconstruction", Some("losses.rgb");
    /// Weighted depth reconstruction `losses.depth * mse`.
    Depth: "depth", "depth", "depth reconstruction", Some("losses.depth");
    /// Weighted sliced Wasserstein texture loss (last scale).
    Swd: "swd", "swd", "SWD texture loss", Some("losses.swd");
    /// Weighted 3D comparison of the reconstruction with the fitted volume.
    Fitted: "fitted", "fitted", "fitted-volume comparison", Some("losses.fitted");
    /// Weighted opacity reconstruction `losses.opacity * mse(opacity, alpha)`.
    Opacity: "opacity", "opacity", "opacity reconstruction", Some("losses.opacity");
    /// Weighted colour-distribution loss of the generated scenes.
    ColourDistribution: "colour_distribution", "colour_dist", "colour distribution",
        Some("losses.colour_distribution");
    /// Weighted chroma-distribution loss of the generated scenes.
    ChromaDistribution: "chroma_distribution", "chroma_dist", "chroma distribution",
        Some("losses.chroma_distribution");
    /// Weighted height-profile loss of the generated scenes.
    HeightProfile: "height_profile", "height", "height profile", Some("losses.height_profile");
    /// Weighted binary-opacity prior of the generated scenes.
    OpacityBinary: "opacity_binary", "binary", "binary-opacity prior",
        Some("losses.opacity_binary");
    /// The 3D critic's loss `mean D3(fake) - mean D3(fitted)`.
    VolumeCritic: "volume_critic", "D3", "3D critic loss", None;
    /// The 3D critic's gradient penalty (weighted).
    VolumePenalty: "volume_penalty", "gp3", "3D critic's gradient penalty",
        Some("critics.gradient_penalty");
    /// The generator's adversarial loss against the 3D critic, weighted by the 3D critic's
    /// weight.
    VolumeAdversarial: "volume_adversarial", "adv3", "3D adversarial loss",
        Some("losses.volume_critic");
}

/// Keys earlier volgens wrote for a term, still read from their logs ([`LossTerm::from_key`]).
const RETIRED_KEYS: [(&str, LossTerm); 1] = [("color", LossTerm::Rgb)];

impl LossTerm {
    /// The term of a log key: its own, or one an earlier volgen wrote for it (`color` before
    /// 2026-12-06 for [`LossTerm::Rgb`]).
    ///
    /// ```
    /// use singrav::train::LossTerm;
    /// assert_eq!(LossTerm::from_key("rgb"), Some(LossTerm::Rgb));
    /// assert_eq!(LossTerm::from_key("color"), Some(LossTerm::Rgb));
    /// assert_eq!(LossTerm::from_key("seconds"), None);
    /// ```
    pub fn from_key(key: &str) -> Option<Self> {
        Self::ALL
            .into_iter()
            .find(|term| term.key() == key)
            .or_else(|| {
                RETIRED_KEYS
                    .iter()
                    .find(|(old, _)| *old == key)
                    .map(|(_, t)| *t)
            })
    }

    fn index(self) -> usize {
        self as usize
    }
}

/// The losses of one iteration (means over its steps): a value for each term it computed.
///
/// ```
/// use singrav::train::{LossTerm, StepLosses};
/// let mut losses = StepLosses::default();
/// losses.set(LossTerm::Rgb, 0.5);
/// assert_eq!(losses.get(LossTerm::Rgb), Some(0.5));
/// assert_eq!(losses.get(LossTerm::Critic), None);
/// assert_eq!(losses.iter().count(), 1);
/// ```
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StepLosses {
    values: [Option<f32>; LossTerm::ALL.len()],
}

impl StepLosses {
    /// The term's value, if this iteration computed it.
    pub fn get(&self, term: LossTerm) -> Option<f32> {
        self.values[term.index()]
    }

    /// Records the term's value.
    pub fn set(&mut self, term: LossTerm, value: f32) {
        self.values[term.index()] = Some(value);
    }

    /// The computed terms and their values, in log order.
    pub fn iter(&self) -> impl Iterator<Item = (LossTerm, f32)> + '_ {
        LossTerm::ALL
            .iter()
            .filter_map(|&term| Some((term, self.get(term)?)))
    }
}

/// Every term's key, `null` where it was not computed: `log.jsonl`'s columns.
impl Serialize for StepLosses {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut map = serializer.serialize_map(Some(LossTerm::ALL.len()))?;
        for term in LossTerm::ALL {
            map.serialize_entry(term.key(), &self.get(term))?;
        }
        map.end()
    }
}

/// One generator step's weighted loss terms, in the order they were added: the order of their
/// sum, so the gradient is the same whatever reports the values.
pub(super) struct StepTerms {
    terms: Vec<(LossTerm, Tensor)>,
}

impl StepTerms {
    pub fn new() -> Self {
        Self { terms: Vec::new() }
    }

    /// Adds a weighted term (a scalar tensor).
    pub fn add(&mut self, term: LossTerm, weighted: Tensor) {
        self.terms.push((term, weighted));
    }

    /// The sum of the terms, `0 + t_1 + t_2 + ...` in order, to differentiate.
    pub fn total(&self, device: &Device) -> Result<Tensor> {
        let mut total = Tensor::zeros((), DType::F32, device)?;
        for (_, value) in &self.terms {
            total = (total + value)?;
        }
        Ok(total)
    }

    /// Every term's value, read back in one transfer.
    pub fn values(&self) -> Result<Vec<(LossTerm, f32)>> {
        if self.terms.is_empty() {
            return Ok(Vec::new());
        }
        let scalars: Vec<Tensor> = self
            .terms
            .iter()
            .map(|(_, value)| value.detach().reshape(1))
            .collect::<candle_core::Result<_>>()?;
        let values = Tensor::cat(&scalars, 0)?.to_vec1::<f32>()?;
        Ok(self
            .terms
            .iter()
            .map(|(term, _)| *term)
            .zip(values)
            .collect())
    }
}

/// Sums of each term over an iteration's generator steps, for their means.
pub(super) struct StepMeans {
    sums: [Option<f32>; LossTerm::ALL.len()],
    steps: usize,
}

impl StepMeans {
    pub fn new() -> Self {
        Self {
            sums: [None; LossTerm::ALL.len()],
            steps: 0,
        }
    }

    /// Adds one step's terms.
    pub fn add(&mut self, terms: &StepTerms) -> Result<()> {
        for (term, value) in terms.values()? {
            let sum = &mut self.sums[term.index()];
            *sum = Some(sum.unwrap_or(0.0) + value);
        }
        self.steps += 1;
        Ok(())
    }

    /// Each term's mean over the steps (a term added in some steps only counts 0 in the
    /// others), into `losses`.
    pub fn write_into(&self, losses: &mut StepLosses) {
        let steps = self.steps.max(1) as f32;
        for term in LossTerm::ALL {
            if let Some(sum) = self.sums[term.index()] {
                losses.set(term, sum / steps);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use candle_core::{Device, Tensor, Var};

    use super::{LossTerm, StepLosses, StepMeans, StepTerms};
    use crate::TrainConfig;

    /// One name per term from the configuration to the log and the progress bar.
    #[test]
    fn every_weight_weighs_one_term_and_every_term_has_names_of_its_own() {
        let config = TrainConfig::preset("tiny").unwrap();
        for (path, _) in config.losses.weights() {
            let weighed: Vec<LossTerm> = LossTerm::ALL
                .into_iter()
                .filter(|term| term.weight() == Some(path))
                .collect();
            assert_eq!(weighed.len(), 1, "{path}: {weighed:?}");
            let key = path.strip_prefix("losses.").unwrap();
            if weighed[0] != LossTerm::VolumeAdversarial {
                // The weight's name is the term's key (the 3D critic's weight weighs the
                // generator's term against that critic, `volume_adversarial`).
                assert_eq!(weighed[0].key(), key);
            }
        }
        for term in LossTerm::ALL {
            if let Some(path) = term.weight() {
                config.clone().with_setting(path, "1").unwrap();
            }
            assert_eq!(LossTerm::from_key(term.key()), Some(term));
        }
        let names: [fn(LossTerm) -> &'static str; 3] =
            [LossTerm::key, LossTerm::short_name, LossTerm::describe];
        for name in names {
            let mut all: Vec<&str> = LossTerm::ALL.into_iter().map(name).collect();
            assert!(all.iter().all(|n| !n.is_empty()));
            all.sort_unstable();
            all.dedup();
            assert_eq!(all.len(), LossTerm::ALL.len(), "{all:?}");
        }
    }

    #[test]
    fn the_log_has_every_term_in_order_with_null_where_not_computed() {
        let mut losses = StepLosses::default();
        losses.set(LossTerm::Rgb, 0.25);
        losses.set(LossTerm::Critic, -1.5);
        let json = serde_json::to_string(&losses).unwrap();
        assert!(json.starts_with(r#"{"critic":-1.5,"penalty":null,"adversarial":null,"rgb":0.25"#));
        assert!(json.ends_with(r#""volume_adversarial":null}"#), "{json}");
        let keys: Vec<&str> = LossTerm::ALL.iter().map(|t| t.key()).collect();
        let mut unique = keys.clone();
        unique.sort();
        unique.dedup();
        assert_eq!(unique.len(), keys.len());
    }

    #[test]
    fn a_steps_total_is_the_sum_in_order_and_its_values_are_read_back_together() {
        let x = Var::new(2.0f32, &Device::Cpu).unwrap();
        let mut terms = StepTerms::new();
        terms.add(LossTerm::Rgb, (x.as_tensor() * 3.0).unwrap());
        terms.add(LossTerm::Depth, x.as_tensor().sqr().unwrap());
        let total = terms.total(&Device::Cpu).unwrap();
        assert_eq!(total.to_scalar::<f32>().unwrap(), 10.0);
        // d/dx (3x + x^2) = 3 + 2x = 7.
        let grads = total.backward().unwrap();
        assert_eq!(grads.get(&x).unwrap().to_scalar::<f32>().unwrap(), 7.0);
        assert_eq!(
            terms.values().unwrap(),
            [(LossTerm::Rgb, 6.0), (LossTerm::Depth, 4.0)]
        );
    }

    #[test]
    fn means_divide_by_every_step_and_report_only_terms_that_were_added() {
        let mut means = StepMeans::new();
        for value in [1.0f32, 3.0] {
            let mut terms = StepTerms::new();
            terms.add(LossTerm::Rgb, Tensor::new(value, &Device::Cpu).unwrap());
            means.add(&terms).unwrap();
        }
        let mut losses = StepLosses::default();
        means.write_into(&mut losses);
        assert_eq!(losses.get(LossTerm::Rgb), Some(2.0));
        assert_eq!(losses.iter().count(), 1);
    }
}
