//! One module per subcommand.

pub mod mesh;
pub mod schema;
pub mod simulate;
