//! Integration tests: ndf.
