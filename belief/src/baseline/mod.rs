//! Yardsticks for the Radon engine (Table III of the paper).
