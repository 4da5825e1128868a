"""Step 5: orthorectification and the comparison of two orthoimages."""
