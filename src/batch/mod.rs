//! Batch regression of fit quality over many scans.
