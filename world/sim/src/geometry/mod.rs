//! Plane geometry shared by the motion models and the event extractor: points
//! and vectors in metres ([`Vec2`]), the rectangular field targets move in
//! ([`Rect`]), and a uniform grid that finds near pairs without looking at all
//! n² of them ([`NeighbourGrid`]). The points and the grid live in
//! `idmesh-extract`, which detects meetings for real trackers too.

mod rect;

pub use idmesh_extract::{NeighbourGrid, Vec2};
pub use rect::Rect;
