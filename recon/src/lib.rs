//! heatrecon
