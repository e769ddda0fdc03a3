pub mod conv3d;
pub mod critic;
pub mod upsampler;
