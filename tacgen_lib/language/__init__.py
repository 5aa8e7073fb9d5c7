"""Tactile-to-language evidence: captions, an offline text encoder and a tactile adapter."""
