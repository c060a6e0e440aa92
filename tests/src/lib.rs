//! Multi-process tests live in `tests/tests/`: each starts the real `idmesh`
//! binary (built by Cargo for this package's tests) and checks what a user
//! would see.
