pub mod conv3d;
