//! Cross-module tests of the simulator.
