//! Shared helpers of the end-to-end tests (the tests live in `tests/tests/`).
