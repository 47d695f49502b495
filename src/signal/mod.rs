//! Windows and amplitude spectra. (Being written.)
