//! Writing animated test scenes as `.glb` files.
