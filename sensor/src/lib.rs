//! # idmesh-sensor — turning the world into events
//!
//! Simulators, real trajectory replay, the acoustic tracking front end and
//! the sensor process that publishes events (issues 3, 4 and 6 build it).
