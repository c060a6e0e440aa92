//! # Acoustic tracking of indistinguishable targets (issue 6)
//!
//! Zhu, Vikram, Fu & Guan, *On Non-Cooperative Multiple-Target Tracking
//! With Wireless Sensor Networks* (IEEE TMC 2014): sensors hear only the
//! sum of the sources around them; blind source separation recovers the
//! individual signals, and the sensing ranges of the sensor groups that
//! hear the same recovered signal locate its target.

pub mod error;
pub mod field;
pub mod metrics;
pub mod parallel;
pub mod pipeline;
pub mod resolution;
pub mod source;

pub use error::AcousticError;
