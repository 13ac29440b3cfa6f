"""What the routes do, one function per operation: the routes validate, call one of these, return a model."""
