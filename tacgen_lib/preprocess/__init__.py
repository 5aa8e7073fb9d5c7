"""The preprocess stage: tactile background subtraction and its variants, frames from edges."""
