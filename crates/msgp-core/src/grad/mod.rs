//! Exact gradients of the MSGP loss.
//!
//! [`dual`] is the reference mechanism: forward-mode vector duals through the generic numerics.

pub mod adjoint;
pub mod dual;
