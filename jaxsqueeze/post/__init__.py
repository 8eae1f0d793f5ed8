"""Post-processing layer: views (pure numpy), cone rotation, plots and ParaView export."""
