//! Motion-state classification. (Being written.)
