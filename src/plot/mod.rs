//! PNG/SVG figures. (Being written.)
