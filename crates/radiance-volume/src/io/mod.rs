//! Reading and writing volumes: safetensors (native, always on), OpenVDB (feature `vdb`) and
//! EXR slice stacks (feature `exr`), plus the atomic-write helper every writer uses.

mod atomic;
#[cfg(feature = "exr")]
pub mod exr_slices;
pub mod safetensors;
#[cfg(feature = "vdb")]
pub mod vdb;

pub use self::safetensors::{safetensors_bytes, write_safetensors};
pub use atomic::{check_writable, remove_file_if_exists, write_atomic, write_bytes_atomic};
#[cfg(feature = "exr")]
pub use exr_slices::ExrSlicesWriter;
#[cfg(feature = "vdb")]
pub use vdb::{VdbStats, VdbWriter};
