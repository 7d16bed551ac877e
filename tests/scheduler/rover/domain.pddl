;; A rover for the sensor tests: it drives between linked places; its battery is sensed.
(define (domain rover)
  (:requirements :strips :typing :durative-actions :numeric-fluents)
  (:types robot place)
  (:predicates (at ?r - robot ?p - place) (link ?a ?b - place))
  (:functions (battery ?r - robot))

  (:durative-action move
    :parameters (?r - robot ?from ?to - place)
    :duration (= ?duration 1)
    :condition (and (at start (at ?r ?from)) (at start (link ?from ?to)))
    :effect (and (at start (not (at ?r ?from)))
                 (at end (at ?r ?to)))))
