//! Plane geometry the extractor and the simulator's motion models share:
//! points and vectors in metres ([`Vec2`]) and a uniform grid that finds
//! near pairs without looking at all n² of them ([`NeighbourGrid`]).

mod grid;
mod vec2;

pub use grid::NeighbourGrid;
pub use vec2::Vec2;
