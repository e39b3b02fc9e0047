//! Speed and accuracy measurements of every knob.
