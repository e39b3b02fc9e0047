//! The NDF at the footprint a renderer sees (Tokuyoshi NDF filtering).
