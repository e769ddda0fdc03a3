//! A training run's directory: the one place the names of its files are spelled. Training
//! writes them, `volgen` and its library users read them through [`RunDir`].

use std::path::{Path, PathBuf};

/// Every generator and critic weight, the optimisers and the progress ([`crate::checkpoint`]).
const CHECKPOINT: &str = "checkpoint.safetensors";
/// The configuration, readable.
const CONFIG: &str = "config.json";
/// One JSON object of losses per iteration.
const LOG: &str = "log.jsonl";
/// The run's copy of the volume fitted to its views, which its 3D comparisons train against.
const FITTED: &str = "fitted.safetensors";
/// The fit of the views without depth that a run with depth from a fit renders its depth from.
const DEPTH_FIT: &str = "depth_fit.safetensors";
/// The pictures of samples after each scale.
const PICTURES: &str = "samples";
/// The quality numbers `volgen eval` measures.
const EVAL: &str = "eval.json";

/// The files of a training run, by what they hold.
///
/// ```
/// use singrav::RunDir;
/// let run = RunDir::new("runs/stones");
/// assert_eq!(run.checkpoint(), std::path::Path::new("runs/stones/checkpoint.safetensors"));
/// assert_eq!(run.scale_picture(2), std::path::Path::new("runs/stones/samples/scale_2.png"));
/// // A model given as its checkpoint file is in the directory that holds it.
/// let same = RunDir::of_model("runs/stones/checkpoint.safetensors".as_ref());
/// assert_eq!(same.root(), std::path::Path::new("runs/stones"));
/// ```
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RunDir {
    root: PathBuf,
}

impl RunDir {
    /// The run in directory `root` (which need not exist yet).
    pub fn new(root: impl Into<PathBuf>) -> Self {
        Self { root: root.into() }
    }

    /// The run a model path names: a run directory, or a checkpoint file inside one (its
    /// parent).
    pub fn of_model(model: &Path) -> Self {
        if model.is_dir() {
            Self::new(model)
        } else {
            Self::new(model.parent().unwrap_or(Path::new("")))
        }
    }

    /// The checkpoint a model path names: the path itself when it is a file, else the run
    /// directory's checkpoint.
    pub fn checkpoint_of(model: &Path) -> PathBuf {
        if model.is_dir() {
            Self::new(model).checkpoint()
        } else {
            model.to_path_buf()
        }
    }

    /// The directory.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// The checkpoint: weights, optimisers, configuration and progress.
    pub fn checkpoint(&self) -> PathBuf {
        self.root.join(CHECKPOINT)
    }

    /// Whether the run has a checkpoint (a run killed before its first one has none).
    pub fn has_checkpoint(&self) -> bool {
        self.checkpoint().is_file()
    }

    /// The configuration as readable JSON (the checkpoint holds it too).
    pub fn config(&self) -> PathBuf {
        self.root.join(CONFIG)
    }

    /// The loss log, one JSON object per iteration ([`crate::train::LossTerm`]'s keys).
    pub fn log(&self) -> PathBuf {
        self.root.join(LOG)
    }

    /// The run's copy of the volume fitted to its views, for the 3D comparisons.
    pub fn fitted(&self) -> PathBuf {
        self.root.join(FITTED)
    }

    /// The fit without depth that depth from a fit renders the views' depth from.
    pub fn depth_fit(&self) -> PathBuf {
        self.root.join(DEPTH_FIT)
    }

    /// The directory of the pictures written after each scale.
    pub fn pictures(&self) -> PathBuf {
        self.root.join(PICTURES)
    }

    /// The picture written after scale `n` (1-based): a real view, the reconstruction and
    /// samples, in a row.
    pub fn scale_picture(&self, n: usize) -> PathBuf {
        self.pictures().join(format!("scale_{n}.png"))
    }

    /// The quality numbers of the run (`volgen eval`).
    pub fn eval(&self) -> PathBuf {
        self.root.join(EVAL)
    }
}

#[cfg(test)]
mod tests {
    use super::RunDir;

    #[test]
    fn a_model_path_names_its_run_whether_directory_or_checkpoint() {
        let tmp = tempfile::tempdir().unwrap();
        let run = RunDir::new(tmp.path());
        assert_eq!(RunDir::of_model(tmp.path()), run);
        std::fs::write(run.checkpoint(), b"").unwrap();
        assert_eq!(RunDir::of_model(&run.checkpoint()), run);
        assert_eq!(RunDir::checkpoint_of(tmp.path()), run.checkpoint());
        let copy = tmp.path().join("copy.safetensors");
        assert_eq!(RunDir::checkpoint_of(&copy), copy);
        // Every file has a name of its own.
        let mut names = vec![
            run.checkpoint(),
            run.config(),
            run.log(),
            run.fitted(),
            run.depth_fit(),
            run.pictures(),
            run.eval(),
        ];
        names.sort();
        names.dedup();
        assert_eq!(names.len(), 7);
    }
}
