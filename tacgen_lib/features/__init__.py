"""The features stage: the DINOv2-architecture ViT, DINO pretraining, frozen-feature extraction."""
