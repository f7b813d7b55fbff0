//! The Q-network.
