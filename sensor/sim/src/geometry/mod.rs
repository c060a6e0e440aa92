//! Plane geometry shared by the motion models and the event extractor: points
//! and vectors in metres ([`Vec2`]), the rectangular field targets move in
//! ([`Rect`]), and a uniform grid that finds near pairs without looking at all
//! n² of them ([`NeighbourGrid`]).

mod grid;
mod rect;
mod vec2;

pub use grid::NeighbourGrid;
pub use rect::Rect;
pub use vec2::Vec2;
