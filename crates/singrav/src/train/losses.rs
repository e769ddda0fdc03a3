//! Losses as data: every term an iteration can report has a name ([`LossTerm`]); a generator
//! step collects its weighted terms in order ([`StepTerms`]), sums them for the backward pass
//! and reads all their values back in one transfer; an iteration reports each term's mean over
//! its steps ([`StepLosses`]). A new loss term is a variant here and one `add` where it is
//! computed.

use candle_core::{DType, Device, Tensor};
use serde::ser::{Serialize, SerializeMap, Serializer};

use crate::error::Result;

/// Every loss term an iteration can report, in the order `log.jsonl` writes them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum LossTerm {
    /// Critic loss `mean D(fake) - mean D(real)` (before the penalty).
    Critic,
    /// The critic's gradient penalty (weighted).
    Penalty,
    /// Generator adversarial loss `-mean D(fake)`.
    Adversarial,
    /// Weighted colour reconstruction `losses.rgb * mse`.
    Colour,
    /// Weighted depth reconstruction `losses.depth * mse`.
    Depth,
    /// Weighted sliced Wasserstein texture loss (last scale).
    Swd,
    /// Weighted 3D comparison of the reconstruction with the fitted volume.
    Fitted,
    /// Weighted opacity reconstruction `losses.opacity * mse(opacity, alpha)`.
    Opacity,
    /// Weighted colour-distribution loss of the generated scenes.
    ColourDistribution,
    /// Weighted chroma-distribution loss of the generated scenes.
    ChromaDistribution,
    /// Weighted height-profile loss of the generated scenes.
    HeightProfile,
    /// Weighted binary-opacity prior of the generated scenes.
    OpacityBinary,
    /// The 3D critic's loss `mean D3(fake) - mean D3(fitted)`.
    VolumeCritic,
    /// The 3D critic's gradient penalty (weighted).
    VolumePenalty,
    /// The generator's weighted adversarial loss against the 3D critic.
    VolumeAdversarial,
}

impl LossTerm {
    /// Every term, in log order.
    pub const ALL: [LossTerm; 15] = [
        LossTerm::Critic,
        LossTerm::Penalty,
        LossTerm::Adversarial,
        LossTerm::Colour,
        LossTerm::Depth,
        LossTerm::Swd,
        LossTerm::Fitted,
        LossTerm::Opacity,
        LossTerm::ColourDistribution,
        LossTerm::ChromaDistribution,
        LossTerm::HeightProfile,
        LossTerm::OpacityBinary,
        LossTerm::VolumeCritic,
        LossTerm::VolumePenalty,
        LossTerm::VolumeAdversarial,
    ];

    /// The term's key in `log.jsonl`.
    pub fn key(self) -> &'static str {
        match self {
            LossTerm::Critic => "critic",
            LossTerm::Penalty => "penalty",
            LossTerm::Adversarial => "adversarial",
            LossTerm::Colour => "color",
            LossTerm::Depth => "depth",
            LossTerm::Swd => "swd",
            LossTerm::Fitted => "fitted",
            LossTerm::Opacity => "opacity",
            LossTerm::ColourDistribution => "colour_distribution",
            LossTerm::ChromaDistribution => "chroma_distribution",
            LossTerm::HeightProfile => "height_profile",
            LossTerm::OpacityBinary => "opacity_binary",
            LossTerm::VolumeCritic => "volume_critic",
            LossTerm::VolumePenalty => "volume_penalty",
            LossTerm::VolumeAdversarial => "volume_adversarial",
        }
    }

    /// The term in words, for messages ("the colour reconstruction is NaN").
    pub fn describe(self) -> &'static str {
        match self {
            LossTerm::Critic => "critic loss",
            LossTerm::Penalty => "gradient penalty",
            LossTerm::Adversarial => "adversarial loss",
            LossTerm::Colour => "colour reconstruction",
            LossTerm::Depth => "depth reconstruction",
            LossTerm::Swd => "SWD loss",
            LossTerm::Fitted => "fitted-volume comparison",
            LossTerm::Opacity => "opacity reconstruction",
            LossTerm::ColourDistribution => "colour distribution",
            LossTerm::ChromaDistribution => "chroma distribution",
            LossTerm::HeightProfile => "height profile",
            LossTerm::OpacityBinary => "binary-opacity prior",
            LossTerm::VolumeCritic => "3D critic loss",
            LossTerm::VolumePenalty => "3D critic's gradient penalty",
            LossTerm::VolumeAdversarial => "3D adversarial loss",
        }
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
/// losses.set(LossTerm::Colour, 0.5);
/// assert_eq!(losses.get(LossTerm::Colour), Some(0.5));
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

    #[test]
    fn the_log_has_every_term_in_order_with_null_where_not_computed() {
        let mut losses = StepLosses::default();
        losses.set(LossTerm::Colour, 0.25);
        losses.set(LossTerm::Critic, -1.5);
        let json = serde_json::to_string(&losses).unwrap();
        assert!(
            json.starts_with(r#"{"critic":-1.5,"penalty":null,"adversarial":null,"color":0.25"#)
        );
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
        terms.add(LossTerm::Colour, (x.as_tensor() * 3.0).unwrap());
        terms.add(LossTerm::Depth, x.as_tensor().sqr().unwrap());
        let total = terms.total(&Device::Cpu).unwrap();
        assert_eq!(total.to_scalar::<f32>().unwrap(), 10.0);
        // d/dx (3x + x^2) = 3 + 2x = 7.
        let grads = total.backward().unwrap();
        assert_eq!(grads.get(&x).unwrap().to_scalar::<f32>().unwrap(), 7.0);
        assert_eq!(
            terms.values().unwrap(),
            [(LossTerm::Colour, 6.0), (LossTerm::Depth, 4.0)]
        );
    }

    #[test]
    fn means_divide_by_every_step_and_report_only_terms_that_were_added() {
        let mut means = StepMeans::new();
        for value in [1.0f32, 3.0] {
            let mut terms = StepTerms::new();
            terms.add(LossTerm::Colour, Tensor::new(value, &Device::Cpu).unwrap());
            means.add(&terms).unwrap();
        }
        let mut losses = StepLosses::default();
        means.write_into(&mut losses);
        assert_eq!(losses.get(LossTerm::Colour), Some(2.0));
        assert_eq!(losses.iter().count(), 1);
    }
}
