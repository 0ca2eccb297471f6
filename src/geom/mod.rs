//! Geometry: grid meshes, OBJ, geometry images (Eq 1, 2), Laplacian, anisotropic boundary maps,
//! and the 3-vector helpers ([`vec3`]) everything geometric shares.

pub mod anisotropy;
mod arap;
pub mod atlas;
mod charts;
pub mod cloth_frame;
pub mod geometry_image;
pub mod laplacian;
pub mod layout;
pub mod mesh;
pub mod obj;
pub mod obj_sequence;
pub mod surface;
pub mod vec3;

pub use geometry_image::Domain;
pub use mesh::GridMesh;
