//! Gear-train model. (Being written.)
