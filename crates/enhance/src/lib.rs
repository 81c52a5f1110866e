//! Stage 2: zero-shot low-light enhancement inside the file ([`enhance`], whose front door
//! is `enhance::enhance`), with the mixture's CPU code and its wgpu twin side by side.
//! Applying and reverting a stored enhancer is in every build; fitting one is feature
//! `encode`. The `gsi` crate re-exports it.

pub mod enhance;
