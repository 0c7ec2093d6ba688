//! The tracer's pipeline tests, one binary: marching cubes against an
//! independent implementation, and the shading pipeline.

mod isosurface;
mod shading_pipeline;
