//! Core data model of stipple: columnar point clouds, the camera convention shared by every
//! backend, and the built-in demo scenes.

pub mod camera;
pub mod cancel;
pub mod cloud;
pub mod colour_map;
pub mod demo;
pub mod grouping;
pub mod lookup;
pub mod mesh;
pub mod normals;
pub mod par;
pub mod rng;
pub mod sys;
pub mod volume;

pub use camera::{Camera, Projection};
pub use cloud::{Bounds, PointCloud};
