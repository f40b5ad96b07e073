"""ABB RAPID: modules and tasks read as targets (object model and columns), their tools,
work objects, confdata and loads, and the lossless writer of compensated modules."""
