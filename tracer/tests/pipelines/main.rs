//! The tracer's pipeline tests, one binary: marching cubes against an
//! independent implementation, the shading pipeline, and volume rendering
//! against an independent ray marcher.

mod isosurface;
mod shading_pipeline;
mod volume_render;
